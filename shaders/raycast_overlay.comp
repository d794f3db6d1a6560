#version 450
// Ray caster overlay pass (shaders/raycast_common.glsl), run only when a frame has
// primitives: per pixel, the HIP, VHIP, plane disc and arrows blended into the linear colour
// of the march (the background where depth < 0) by depth, and the final RGBA8 written.
//
// Two forms (specialization constant 9, STAGE), the same floats in the same order:
// - STAGE 0: one pass; every invocation reads every primitive.
// - Stages, one dispatch each (engine/raycast.cpp, record_overlay): BEGIN over the
//   primitives' rectangle puts each pixel's colour and nearest depth in binding 16; then one
//   dispatch per primitive of the opaque list (OPAQUE), then of the blending list (BLEND),
//   each over that primitive's own rectangle and made for its kind (specialization constant
//   10, KIND: only that kind's intersection; on llvmpipe every arm of an `if` runs, masked,
//   and the two-point kinds' are most of the code); END packs binding 16 into the image.
//   A primitive misses every pixel outside its rectangle (the same box projection as the
//   whole rectangle's), so skipping them there changes nothing.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

// The one pass: rows of ISOTOUCH_RAYCAST_WG_X pixels; the stages: tiles of
// ISOTOUCH_RAYCAST_TILE pixels square (specialization constants 11 and 12: a primitive's
// rectangle is often narrower than a row, and a lane past it is work wasted).
layout(local_size_x = ISOTOUCH_RAYCAST_WG_X, local_size_y = ISOTOUCH_RAYCAST_WG_Y, local_size_z = 1,
       local_size_x_id = 11, local_size_y_id = 12) in;

#include "raycast_common.glsl"

#define STAGE_ONE_PASS 0u
#define STAGE_BEGIN 1u
#define STAGE_OPAQUE 2u
#define STAGE_BLEND 3u
#define STAGE_END 4u
layout(constant_id = 9) const uint STAGE = STAGE_ONE_PASS;
layout(constant_id = 10) const uint KIND = 0u;
// Per pixel of the stages: the linear colour so far (rgb) and the nearest depth t [m] (w,
// +inf: none). Not read outside the frame's stages.
layout(std430, set = 0, binding = 16) buffer OverlayState { vec4 overlay_state[]; };

// The opaque loop's step for primitive q: the nearest opaque surface so far wins.
void opaque_step(RaycastPrim q, uint kind, vec3 eye, vec3 dir, inout vec3 colour, inout float t_best) {
  if (q.alpha < 1.0) return;
  vec4 h = intersect_prim_as(q, eye, dir, kind);
  if (h.x > 0.0 && h.x < t_best) {
    t_best = h.x;
    colour = shade(vec3(q.cr, q.cg, q.cb), h.yzw, dir);
  }
}

// The blending loop's step: a translucent primitive in front of the nearest surface blends
// in; an x-ray one behind it shows faintly.
void blend_step(RaycastPrim q, uint kind, vec3 eye, vec3 dir, inout vec3 colour, float t_best) {
  bool xray = q.pad0 > 0.0;
  if (q.alpha >= 1.0 && !xray) return;
  vec4 h = intersect_prim_as(q, eye, dir, kind);
  if (!(h.x > 0.0)) return;
  float a = h.x < t_best ? q.alpha : (xray ? 0.35 : 0.0);
  if (q.alpha >= 1.0 && h.x <= t_best) a = 0.0;  // drawn in the opaque pass
  if (a > 0.0) colour = mix(colour, shade(vec3(q.cr, q.cg, q.cb), h.yzw, dir), a);
}

void main() {
  // The dispatch covers only the pixels the primitives' box (a stage's primitive's box)
  // projects to, from (x0, y0) (engine/raycast.cpp); every other pixel keeps the march's colour.
  uvec2 px = gl_GlobalInvocationID.xy + uvec2(pc.x0, pc.y0);
  if (px.x >= P.width || px.y >= P.height) return;
  uint pix = px.y * P.width + px.x;
  if (STAGE == STAGE_END) {
    image[pix] = pack_rgba(overlay_state[pix].rgb);
    return;
  }
  if (STAGE == STAGE_BEGIN) {
    float t_hit = depth[pix];
    vec3 colour = t_hit >= 0.0 ? vec3(lin_r[pix], lin_g[pix], lin_b[pix]) : vec3(P.bg_r, P.bg_g, P.bg_b);
    overlay_state[pix] = vec4(colour, t_hit >= 0.0 ? t_hit : kInf);
    return;
  }
  Ray r = make_ray(px);
  vec3 eye = r.eye, dir = r.dir;
  if (STAGE == STAGE_OPAQUE || STAGE == STAGE_BLEND) {  // one primitive: binding 3's entry prim_count
    vec4 s = overlay_state[pix];
    vec3 colour = s.rgb;
    float t_best = s.w;
    RaycastPrim q = prim_at(pc.prim_count);
    if (STAGE == STAGE_OPAQUE) opaque_step(q, KIND, eye, dir, colour, t_best);
    else blend_step(q, KIND, eye, dir, colour, t_best);
    overlay_state[pix] = vec4(colour, t_best);
    return;
  }
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
    opaque_step(q, q.kind, eye, dir, colour, t_best);
  }
  for (uint i = n_opaque; i < np; ++i) {
    RaycastPrim q = prim_at(i);
    blend_step(q, q.kind, eye, dir, colour, t_best);
  }
  image[pix] = pack_rgba(colour);
}
