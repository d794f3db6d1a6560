#version 450
// Ray caster march pass (shaders/raycast_common.glsl): one invocation per pixel (with tile
// starts, per pixel of the tiles raycast_tiles.comp listed).
// A pixel whose ray reaches an inside lattice sample k (sample 0 included) is refined and
// shaded here (shade_hit: colour and depth); a ray whose skipping march llvmpipe's loop
// budget stopped is appended to the hit list, marked, for raycast_shade.comp to finish.
// Nothing else is written (the host fills image and depth with the background before: a
// store is a per-lane scatter on llvmpipe, masked or not). The pipeline with SKIP_EMPTY
// skips empty space (march_skip); both marches return the same k.
#extension GL_GOOGLE_include_directive : require
#ifdef ISOTOUCH_COUNT_FETCHES  // (raycast_common.glsl)
#extension GL_KHR_shader_subgroup_basic : require
#endif
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_RAYCAST_WG_X, local_size_y = ISOTOUCH_RAYCAST_WG_Y, local_size_z = 1) in;

#include "raycast_common.glsl"

// Specialization constant: one pipeline with skipping (march_skip), one without (march): each
// carries only its own loop (on llvmpipe a loop not taken still runs once, masked).
layout(constant_id = 0) const bool SKIP_EMPTY = true;
// Specialization constant 5 (with SKIP_EMPTY): tile starts. One workgroup per tile listed
// by raycast_tiles.comp (indirect dispatch; workgroup (x, y) of a grid groups_x wide is
// list entry y groups_x + x), invocation i at pixel (i % TILE, i / TILE) of its tile: the 8
// lanes of a vector are one tile row. Each pixel starts from its block's start (the block
// pass of raycast_tiles.comp, for the same list entry).
layout(constant_id = 5) const bool TILED = false;
// Specialization constant 8: shade_hit writes the linear colour too (bindings 6-8), for the
// overlay pass (only frames with primitives: a store is a per-lane scatter on llvmpipe).
layout(constant_id = 8) const bool WRITE_LINEAR = false;

#ifdef ISOTOUCH_COUNT_FETCHES
#define PASS_MAIN march_pixel
#else
#define PASS_MAIN main
#endif
void PASS_MAIN() {
  uvec2 px;
  uint start_at = 0u;  // TILED: the entry of binding 13 with this pixel's block start
  if (TILED) {
    uint j = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (j >= tctr.count) return;
    uint tl = tile_list[j];
    uint i = gl_LocalInvocationID.x;
    uvec2 in_tile = uvec2(i % ISOTOUCH_RAYCAST_TILE, i / ISOTOUCH_RAYCAST_TILE);
    px = uvec2(tl & 0xffffu, tl >> 16) * ISOTOUCH_RAYCAST_TILE + in_tile;
    const uint per_side = ISOTOUCH_RAYCAST_TILE / ISOTOUCH_RAYCAST_BLOCK;
    uint tiles = ((P.width + ISOTOUCH_RAYCAST_TILE - 1u) / ISOTOUCH_RAYCAST_TILE) *
                 ((P.height + ISOTOUCH_RAYCAST_TILE - 1u) / ISOTOUCH_RAYCAST_TILE);
    uvec2 block = in_tile / ISOTOUCH_RAYCAST_BLOCK;
    start_at = tiles + j * per_side * per_side + block.y * per_side + block.x;
  } else {
    px = gl_GlobalInvocationID.xy + uvec2(pc.x0, pc.y0);
  }
  if (px.x >= P.width || px.y >= P.height) return;
  uint pix = px.y * P.width + px.x;
  init_globals();

  Ray r = make_ray(px);
  if (!(r.t0 <= r.t1)) return;
  // Samples 0 .. K; a hit at sample 0 is the ray's entry point (the cut face where t0 is
  // on the clip plane).
  int k_hit;
  if (SKIP_EMPTY) {
    precise vec3 inv_d = 1.0 / r.d;  // +-inf on an axis the ray is parallel to (not used there)
    g_inv_d = inv_d;
    // Rounding allowance: 1/32 voxel + 4e-6 (34 float ulps) of the largest index-space
    // magnitude along the ray (eye, far end of the box, grid size).
    vec3 e = r.e;
    float mag = max(max(max(abs(e.x), abs(e.y)), abs(e.z)), max(max(float(P.nx), float(P.ny)), float(P.nz)));
    precise float eps = 0.03125 + 4e-6 * (mag + r.t1 * r.dl);
    // Only the samples in the active cells' box can be inside (a cell outside it is
    // inactive; outside the cells the field is the background, outside too, or the border
    // cells would be active): from one sample before the ray enters it to one after it
    // leaves (a whole step of margin for the rounding of the interval).
    vec2 ta = box_interval_of(r.e, r.d, vec3(P.act_lo_x, P.act_lo_y, P.act_lo_z),
                              vec3(P.act_hi_x, P.act_hi_y, P.act_hi_z));
    // (clamped in float first: a far eye must not overflow the int conversion)
    int k0 = int(clamp(floor((ta.x - r.t0) / r.h) - 1.0, 0.0, float(r.K + 1)));
    // Block starts: no sample of this ray before its block's t_block can be inside
    // (raycast_tiles.comp; +inf: none can be); start two samples before it (the rounding of
    // the division).
    if (TILED) {
      float t_block = tile_t[start_at];
      k0 = max(k0, int(clamp(floor((t_block - r.t0) / r.h) - 1.0, 0.0, float(r.K + 1))));
    }
    int k1 = int(clamp(ceil((ta.y - r.t0) / r.h) + 1.0, -1.0, float(r.K)));
    k_hit = ta.x <= ta.y ? march_skip(r.e, r.d, r.t0, r.t1, r.h, k0, k1, eps) : -1;
  } else {
    k_hit = march(r.e, r.d, r.t0, r.t1, r.h, r.K);
  }
  bool cap = k_hit == 0 && r.cap_entry;
  // k_hit <= -2: the skipping march ran out of llvmpipe's loop budget at sample -(k_hit + 2);
  // the shade pass finishes the ray from there (bit 30).
  bool redo = k_hit <= -2;
  if (k_hit >= 0) shade_hit(r, pix, k_hit, cap, WRITE_LINEAR);
  if (redo) {
    uint slot = atomicAdd(ctr.count, 1u);
    hits[slot] = pix;
    hit_k[pix] = uint(-(k_hit + 2)) | 0x40000000u;
  }
}

#ifdef ISOTOUCH_COUNT_FETCHES
void main() {
  march_pixel();
  atomicAdd(fetches_march, g_fetches - g_shade_fetches);
  atomicAdd(vector_fetches_march, g_vector_fetches - g_shade_vector_fetches);
  atomicAdd(fetches_shade, g_shade_fetches);
  atomicAdd(vector_fetches_shade, g_shade_vector_fetches);
  atomicAdd(shaded, g_shaded);
}
#endif
