#version 450
// Ray caster shade pass (shaders/raycast_common.glsl): one invocation per hit
// pixel of raycast_march.comp (indirect dispatch). Rebuilds the pixel's ray (the same float
// operations as the march), refines the hit in the bracket [t_{k-1}, t_k] (sample 0: t0,
// no refinement), shades it and writes colour and depth.
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
  // Sample 0 has no bracket: refine() of [t0, t0] returns t0 (and loads the block around it,
  // which the normal reads). Unconditional: on llvmpipe an `if` would not skip it anyway.
  float ta = k > 0 ? lattice_t(r.t0, r.t1, r.h, k - 1) : r.t0;
  float tb = k > 0 ? lattice_t(r.t0, r.t1, r.h, k) : r.t0;
  float t_hit = refine(r.e, r.d, ta, tb);
  // The cut face is flat (the clip plane's normal, cap colour): one shade() of whichever
  // applies (on llvmpipe both arms of an `if` run, so two calls would cost two).
  vec3 n = surface_normal_block(ray_point(r.e, r.d, t_hit));  // the block holds the hit's cell
  vec3 albedo = vec3(P.surf_r, P.surf_g, P.surf_b);
  if (cap) {
    n = vec3(P.clip_nx, P.clip_ny, P.clip_nz);
    albedo = vec3(P.cap_r, P.cap_g, P.cap_b);
  }
  vec3 colour = shade(albedo, n, r.dir);
  depth[pix] = t_hit;
  if (WRITE_LINEAR) {
    lin_r[pix] = colour.r;
    lin_g[pix] = colour.g;
    lin_b[pix] = colour.b;
  }
  image[pix] = pack_rgba(colour);
}

#ifdef ISOTOUCH_COUNT_FETCHES
void main() {
  shade_pixel();
  atomicAdd(fetches_shade, g_fetches);
  atomicAdd(vector_fetches_shade, g_vector_fetches);
}
#endif
