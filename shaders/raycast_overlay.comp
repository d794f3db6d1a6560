#version 450
// Ray caster overlay pass (shaders/raycast_common.glsl), run only when a frame has
// primitives: one invocation per pixel blends the HIP, VHIP, plane disc and arrows into the
// linear colour of pass 3 (the background where depth < 0) by depth, and writes the final RGBA8.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_RAYCAST_WG_X, local_size_y = ISOTOUCH_RAYCAST_WG_Y, local_size_z = 1) in;

#include "raycast_common.glsl"

void main() {
  // The dispatch covers only the pixels the primitives' box projects to, from (x0, y0)
  // (engine/raycast.cpp); every other pixel keeps the shade pass's colour.
  uvec2 px = gl_GlobalInvocationID.xy + uvec2(pc.x0, pc.y0);
  if (px.x >= P.width || px.y >= P.height) return;
  uint pix = px.y * P.width + px.x;
  Ray r = make_ray(px);
  vec3 eye = r.eye, dir = r.dir;
  float t_hit = depth[pix];
  vec3 colour = t_hit >= 0.0 ? vec3(lin_r[pix], lin_g[pix], lin_b[pix]) : vec3(P.bg_r, P.bg_g, P.bg_b);
  float t_best = t_hit >= 0.0 ? t_hit : kInf;
  // Opaque primitives by depth, then translucent ones (and x-ray: opaque primitives hidden
  // behind the surface, shown faintly) blended in order. Binding 3 holds two lists
  // (engine/raycast.cpp): the opaque loop's (alpha 1) and then the blending loop's (alpha < 1
  // or x-ray); prim_count: the first's length << 16 | both lengths.
  uint np = min(pc.prim_count & 0xffffu, 2u * ISOTOUCH_RAYCAST_MAX_PRIMS);
  uint n_opaque = min(pc.prim_count >> 16, np);
  for (uint i = 0u; i < n_opaque; ++i) {
    RaycastPrim q = prim_at(i);
    if (q.alpha < 1.0) continue;
    vec4 h = intersect_prim(q, eye, dir);
    if (h.x > 0.0 && h.x < t_best) {
      t_best = h.x;
      colour = shade(vec3(q.cr, q.cg, q.cb), h.yzw, dir);
    }
  }
  for (uint i = n_opaque; i < np; ++i) {
    RaycastPrim q = prim_at(i);
    bool xray = q.pad0 > 0.0;
    if (q.alpha >= 1.0 && !xray) continue;
    vec4 h = intersect_prim(q, eye, dir);
    if (!(h.x > 0.0)) continue;
    float a = h.x < t_best ? q.alpha : (xray ? 0.35 : 0.0);
    if (q.alpha >= 1.0 && h.x <= t_best) a = 0.0;  // drawn in the opaque pass
    if (a > 0.0) colour = mix(colour, shade(vec3(q.cr, q.cg, q.cb), h.yzw, dir), a);
  }
  image[pix] = pack_rgba(colour);
}
