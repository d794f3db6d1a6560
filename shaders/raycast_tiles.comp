#version 450
// Ray caster pass 0 (shaders/raycast_common.glsl), with skipping only: one invocation per
// tile of ISOTOUCH_RAYCAST_TILE x ISOTOUCH_RAYCAST_TILE pixels writes t_tile (binding 13):
// no lattice sample of any of the tile's rays with t < t_tile can be inside (+inf: none
// can), and lists the tiles whose t_tile is finite (binding 15, count in binding 14). The
// march pass then runs only over the listed tiles' pixels (on llvmpipe every vector of 8
// invocations runs all of a pass's straight-line code, a pixel that returns early too: only
// a smaller dispatch saves it) and starts each pixel's skipping march two samples before
// t_tile, so it finds the same first inside sample with fewer distance jumps: the picture
// is unchanged. A second dispatch of this shader (the block pass, BLOCKS below) refines
// each listed tile's start per block of ISOTOUCH_RAYCAST_BLOCK^2 pixels, and the march
// starts from its block's.
//
// Cone stepping: every ray of the tile has a unit direction within `chord` (Euclidean
// distance between unit vectors) of the tile's centre direction c, the largest over the
// tile's four corner pixels (the directions within an angle of c cut the image plane in a
// convex set, so the rectangle of pixel centres lies in it when its corners do). At
// parameter t [m] a tile ray's index-space point is then within t w (chessboard, w = chord
// * max(inv_spacing), inflated for rounding) of the centre ray's point e + t dc.
//   1. Entry: the cone's cross-section box [e + t dc - t w, e + t dc + t w] meets the box A
//      of the samples that can be inside (the active cells' box within the sampling box
//      [-1, n], grown by eps) only for t in an interval [t_in, t_out] (per axis two linear
//      inequalities in t); before t_in and after t_out no sample of the tile is in A.
//   2. Steps from t_in: at the centre point p (clamped into A: for a sample q in A,
//      |q - clamp(p)| <= |q - p| per axis) the cell distance D says every cell within D - 1
//      of p's cell is inactive, so the samples of all of the tile's rays with t' in
//      [t, t + s / (|dc|_inf + w)] are in inactive cells, s = D - 1 - eps - t w; the march
//      moves on by that much and stops where s <= 0 (the cone has reached an active cell's
//      neighbourhood) or after ISOTOUCH_RAYCAST_TILE_STEPS steps.
// eps: the march's rounding allowance (1/32 voxel + 34 float ulps of the magnitudes), which
// covers the float rounding of the pixels' sample points and of this pass's own.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

// The workgroup size: specialization constant 6 (WG_X for tiles, the blocks of one tile for BLOCKS).
layout(local_size_x_id = 6, local_size_y = 1, local_size_z = 1) in;

#include "raycast_common.glsl"

// Specialization constant 5: the block pass, over the tiles listed by the tile pass (a
// dispatch of raycast_args.comp: whole tiles per workgroup), one invocation per block of
// ISOTOUCH_RAYCAST_BLOCK^2 pixels (x fastest): the same cone march for the block's rays, from its tile's start (no
// sample of the block's rays before it can be inside: they are some of the tile's rays),
// with a cone about TILE / BLOCK times narrower, so it stops that much nearer the first
// active cells. Written after the tiles' starts: entry tile_count + BLOCKS_PER_TILE j + i
// of binding 13 for block i of list entry j (the march's workgroup j reads them).
layout(constant_id = 5) const bool BLOCKS = false;
const uint kBlocksPerSide = ISOTOUCH_RAYCAST_TILE / ISOTOUCH_RAYCAST_BLOCK;
// The block pass's cone march steps at most (it starts from its tile's start: the first
// steps gain the most).
const int BLOCK_STEPS = 8;

// The unit direction of the image-plane offset (sx, sy) [pixels], as make_ray computes it.
vec3 plane_dir(float sx, float sy) {
  vec3 fwd = vec3(P.fwd_x, P.fwd_y, P.fwd_z), right = vec3(P.right_x, P.right_y, P.right_z);
  vec3 up = vec3(P.up_x, P.up_y, P.up_z);
  precise vec3 dsum = fwd * P.focal_px + right * sx + up * sy;
  return dot_safe_normalize(dsum);
}

float chord(vec3 a, vec3 b) {
  precise vec3 v = a - b;
  return sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
}

// The cone's interval [t_in, t_out] (t >= 0) in which its cross-section box (half-width
// t w) meets the box [lo, hi]; t_in > t_out: never.
vec2 cone_interval(vec3 e, vec3 dc, float w, vec3 lo, vec3 hi) {
  float tin = 0.0, tout = kInf;
  for (int a = 0; a < 3; ++a) {
    // e + t (dc + w) >= lo and e + t (dc - w) <= hi on axis a.
    precise float k1 = dc[a] + w, r1 = lo[a] - e[a];
    precise float k2 = dc[a] - w, r2 = hi[a] - e[a];
    if (k1 > 0.0) tin = max(tin, r1 / k1);
    else if (k1 < 0.0) tout = min(tout, r1 / k1);
    else if (r1 > 0.0) tout = -1.0;
    if (k2 > 0.0) tout = min(tout, r2 / k2);
    else if (k2 < 0.0) tin = max(tin, r2 / k2);
    else if (r2 < 0.0) tout = -1.0;
  }
  return vec2(tin, tout);
}

// The cone march of the pixels [pix0, pix0 + span] per axis from t_from (no sample of
// their rays before t_from can be inside): the start of those pixels (+inf: none can be inside).
float cone_start(uvec2 pix0, float span, float t_from, int steps) {
  // The corner pixels' image-plane offsets (make_ray's sx, sy) and the centre between them.
  float sx0 = (float(pix0.x) + 0.5) - 0.5 * float(P.width);
  float sy0 = 0.5 * float(P.height) - (float(pix0.y) + 0.5);
  vec3 c = plane_dir(sx0 + 0.5 * span, sy0 - 0.5 * span);
  float ch = max(max(chord(plane_dir(sx0, sy0), c), chord(plane_dir(sx0 + span, sy0), c)),
                 max(chord(plane_dir(sx0, sy0 - span), c), chord(plane_dir(sx0 + span, sy0 - span), c)));
  vec3 inv_sp = vec3(P.inv_sp_x, P.inv_sp_y, P.inv_sp_z);
  // Rounding of the directions and of the chord: a relative 1e-3 and 1e-6 more.
  precise float w = (ch * 1.001 + 1e-6) * max(max(inv_sp.x, inv_sp.y), inv_sp.z);
  vec3 eye = vec3(P.eye_x, P.eye_y, P.eye_z);
  precise vec3 e = (eye - vec3(P.origin_x, P.origin_y, P.origin_z)) * inv_sp;
  precise vec3 dc = c * inv_sp;
  float dinf = max(max(abs(dc.x), abs(dc.y)), abs(dc.z));
  // A: the active cells' box within the sampling box.
  vec3 lo = max(vec3(P.act_lo_x, P.act_lo_y, P.act_lo_z), vec3(-1.0));
  vec3 hi = min(vec3(P.act_hi_x, P.act_hi_y, P.act_hi_z), vec3(float(P.nx), float(P.ny), float(P.nz)));
  // eps as the march's (raycast_march.comp: 1/32 + 4e-6 (mag + t |d|)) for any sample in the
  // sampling box: there t |d| <= |e| + |sample| <= sqrt(3) (2 mag + 1).
  float mag = max(max(max(abs(e.x), abs(e.y)), abs(e.z)), max(max(float(P.nx), float(P.ny)), float(P.nz)));
  precise float eps = 0.03125 + 4e-6 * (5.0 * mag + 2.0);
  vec2 tc = cone_interval(e, dc, w, lo - eps, hi + eps);
  float t_start = kInf;
  if (tc.x <= tc.y) {
    float t = max(tc.x, t_from);
    for (int i = 0; i < steps; ++i) {
      if (t > tc.y) {  // past A: no sample of these rays can be inside
        t = kInf;
        break;
      }
      precise vec3 p = e + t * dc;
      vec3 pb = clamp(p, lo, hi);
      uint D = cell_dist(ivec3(floor(pb)));
      precise float s = float(D) - 1.0 - eps - t * w;
      if (!(s > 0.0)) break;
      precise float dt = s / (dinf + w);
      t = t + dt;
    }
    t_start = t;
  }
  return t_start;
}

void main() {
  uint tiles_x = (P.width + ISOTOUCH_RAYCAST_TILE - 1u) / ISOTOUCH_RAYCAST_TILE;
  uint tiles_y = (P.height + ISOTOUCH_RAYCAST_TILE - 1u) / ISOTOUCH_RAYCAST_TILE;
  init_globals();
  if (BLOCKS) {
    const uint per_tile = kBlocksPerSide * kBlocksPerSide;
    uint j = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * (gl_WorkGroupSize.x / per_tile) +
             gl_LocalInvocationID.x / per_tile;
    if (j >= tctr.count) return;
    uint tl = tile_list[j];
    uvec2 tile = uvec2(tl & 0xffffu, tl >> 16);
    uint i = gl_LocalInvocationID.x % per_tile;
    uvec2 pix0 = tile * ISOTOUCH_RAYCAST_TILE + uvec2(i % kBlocksPerSide, i / kBlocksPerSide) * ISOTOUCH_RAYCAST_BLOCK;
    float t_tile = tile_t[tile.y * tiles_x + tile.x];
    tile_t[tiles_x * tiles_y + j * kBlocksPerSide * kBlocksPerSide + i] =
        cone_start(pix0, float(ISOTOUCH_RAYCAST_BLOCK - 1u), t_tile, BLOCK_STEPS);
    return;
  }
  uvec2 tile = gl_GlobalInvocationID.xy + uvec2(pc.x0, pc.y0);
  if (tile.x >= tiles_x || tile.y >= tiles_y) return;
  float t_tile = cone_start(tile * ISOTOUCH_RAYCAST_TILE, float(ISOTOUCH_RAYCAST_TILE - 1u), 0.0, int(ISOTOUCH_RAYCAST_TILE_STEPS));
  tile_t[tile.y * tiles_x + tile.x] = t_tile;
  if (t_tile != kInf) tile_list[atomicAdd(tctr.count, 1u)] = (tile.y << 16) | tile.x;
}
