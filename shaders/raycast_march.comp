#version 450
// Ray caster pass 1 of 4 (issue 10; shaders/raycast_common.glsl): one invocation per pixel.
// A pixel whose ray reaches an inside lattice sample k (sample 0 included) is appended to
// the hit list, with k in hit_k, for raycast_shade.comp to refine and shade; nothing else is
// written (the host fills image and depth with the background before: a store is a per-lane
// scatter on llvmpipe, masked or not). With ISOTOUCH_RAYCAST_SKIP the march skips empty
// space (march_skip); both marches return the same k.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_RAYCAST_WG_X, local_size_y = ISOTOUCH_RAYCAST_WG_Y, local_size_z = 1) in;

#include "raycast_common.glsl"

void main() {
  uvec2 px = gl_GlobalInvocationID.xy + uvec2(pc.x0, pc.y0);
  if (px.x >= P.width || px.y >= P.height) return;
  uint pix = px.y * P.width + px.x;
  init_globals();

  Ray r = make_ray(px);
  if (!(r.t0 <= r.t1)) return;
  // Samples 0 .. K; a hit at sample 0 is the ray's entry point (the cut face where t0 is
  // on the clip plane).
  int k_hit;
  if ((pc.flags & ISOTOUCH_RAYCAST_SKIP) != 0u) {
    precise vec3 inv_d = 1.0 / r.d;  // +-inf on an axis the ray is parallel to (not used there)
    g_inv_d = inv_d;
    // Rounding allowance: 1/32 voxel + 4e-6 (34 float ulps) of the largest index-space
    // magnitude along the ray (eye, far end of the box, grid size).
    vec3 e = r.e;
    float mag = max(max(max(abs(e.x), abs(e.y)), abs(e.z)), max(max(float(P.nx), float(P.ny)), float(P.nz)));
    precise float eps = 0.03125 + 4e-6 * (mag + r.t1 * r.dl);
    k_hit = march_skip(r.e, r.d, r.t0, r.t1, r.h, r.K, eps);
  } else {
    k_hit = march(r.e, r.d, r.t0, r.t1, r.h, r.K);
  }
  bool cap = k_hit == 0 && r.cap_entry;
  if (k_hit >= 0) {
    uint slot = atomicAdd(ctr.count, 1u);
    hits[slot] = pix;
    hit_k[pix] = uint(k_hit) | (cap ? 0x80000000u : 0u);
  }
}
