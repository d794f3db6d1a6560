#version 450
// Ray caster shade pass (shaders/raycast_common.glsl): one invocation per pixel that
// raycast_march.comp listed (indirect dispatch): rays whose skipping march llvmpipe's loop
// budget stopped (the march shades its other hits itself). Rebuilds the pixel's ray (the
// same float operations as the march), finishes its march with the plain one (a new
// dispatch, a new budget) and, for a hit, shade_hit: refinement, normal, shading, colour
// and depth.
#extension GL_GOOGLE_include_directive : require
#ifdef ISOTOUCH_COUNT_FETCHES  // (raycast_common.glsl)
#extension GL_KHR_shader_subgroup_basic : require
#endif
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_RAYCAST_SHADE_WG, local_size_y = 1, local_size_z = 1) in;

#include "raycast_common.glsl"

// Specialization constant: the linear colour (bindings 6-8) is written only for the overlay
// pass, i.e. when the frame has primitives (a store is a per-lane scatter on llvmpipe).
layout(constant_id = 0) const bool WRITE_LINEAR = true;

#ifdef ISOTOUCH_COUNT_FETCHES
#define PASS_MAIN shade_pixel
#else
#define PASS_MAIN main
#endif
void PASS_MAIN() {
  uint j = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * ISOTOUCH_RAYCAST_SHADE_WG +
           gl_LocalInvocationID.x;  // a 2-D grid of workgroups (raycast_args.comp)
  if (j >= ctr.count) return;
  uint pix = hits[j];
  uint kc = hit_k[pix];
  int k = int(kc & 0x3fffffffu);
  bool cap = (kc & 0x80000000u) != 0u;
  bool redo = (kc & 0x40000000u) != 0u;
  init_globals();
  Ray r = make_ray(uvec2(pix % P.width, pix / P.width));
  // A skipping march the loop budget stopped at sample k: finish it with the plain march (one
  // flat loop, within this dispatch's own budget); no inside sample: the pixel stays background.
  if (redo) {
    k = march_from(r.e, r.d, r.t0, r.t1, r.h, k, r.K);
    cap = k == 0 && r.cap_entry;
  }
  if (k < 0) return;
  shade_hit(r, pix, k, cap, WRITE_LINEAR);
}

#ifdef ISOTOUCH_COUNT_FETCHES
void main() {
  shade_pixel();
  atomicAdd(fetches_shade, g_fetches);
  atomicAdd(vector_fetches_shade, g_vector_fetches);
  atomicAdd(shaded, g_shaded);
}
#endif
