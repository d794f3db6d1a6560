#version 450
// First-hit isosurface ray caster, one invocation per pixel (issue 10).
//
// Field: the trilinear interpolation of the float voxels (voxel centres at integer index,
// every voxel outside the grid reads `background`), i.e. the value field the servo feels
// (core::FieldView). Inside = inside_sign * (value - tau) > 0; NaN is outside.
//
// Ray: p(t) = eye + t dir in grid-world [m] (dir unit), marched in index space
// p_idx(t) = e + t d with e = (eye - origin) * inv_sp, d = dir * inv_sp, t in metres.
// Samples on one lattice t_k = min(t0 + k h, t1), h = step_vox / |d| (index-space step
// `step_vox` voxels), over [t0, t1] = the ray inside the box [-1, n] (the one-voxel band
// where the border voxels blend with the background) and, with the clip flag, inside
// the kept half-space dot(n, p) + d <= 0. The first inside sample t_k is refined by 8
// bisections of [t_{k-1}, t_k] and one secant step (bracket h / 256: 0.002 voxel at
// h = 0.5 voxel). A ray that starts inside (at the clip plane) hits there: the cut face.
//
// Empty-space skipping: a 3D DDA over the 8^3 brick grid (brick c covers index
// [8c, 8c + 8] per axis; the box band [-1, 0) and [8 bx, n] belong to the edge bricks).
// A brick whose range (min, max, halo 1, edge bricks widened by the background on the
// host) is all outside is skipped; in the others the same lattice samples are taken as
// without skipping (k from one before the brick to one after), so skipping on and off
// give the same image: a sample in a skipped brick is outside either way.
// Second level: inside an active brick a DDA over its sub-cells (SUB^3 voxels, ranges
// covering [SUB c, SUB c + SUB], built on the host) samples only active sub-cells, again
// from one sample before to one after; k_next keeps each lattice sample evaluated once.
//
// The CPU reference (engine/raycast_cpu.cpp) does the same float operations in the same
// order; `precise` forbids FMA contraction here, -ffp-contract=off there.
#extension GL_GOOGLE_include_directive : require
#include "isotouch_shared.h"

layout(local_size_x = ISOTOUCH_RAYCAST_WG_X, local_size_y = ISOTOUCH_RAYCAST_WG_Y, local_size_z = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer ParamsBuf { RaycastParams P; };
layout(std430, set = 0, binding = 1) readonly buffer Values { float vals[]; };
layout(std430, set = 0, binding = 2) readonly buffer Bricks { float brick[]; };
layout(std430, set = 0, binding = 3) readonly buffer Prims { RaycastPrim prims[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Image { uint image[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Depth { float depth[]; };
layout(push_constant) uniform Push { RaycastPush pc; };

#define kInf uintBitsToFloat(0x7f800000u)

// Per-invocation copies of the parameters the inner loops read (an SSBO read per use
// is a gather on a CPU Vulkan device).
ivec3 g_n;
float g_bg, g_tau, g_sign;
uint g_nx, g_ny;
ivec3 g_ns;       // sub-cells per axis: ceil(n / SUB)
vec3 g_inv_d;     // 1 / d per axis (the DDA boundaries: (plane - e) * inv)
uint g_sub_base;  // first sub-cell range in binding 2 (after the brick ranges), in ranges
const int SUB = int(ISOTOUCH_RAYCAST_SUB);

// The memory seam: the only function that reads voxel memory. A bricked snapshot
// (core/brick_field.h) replaces the body with one brick-table lookup + pool read.
// Branch-free: the index is clamped into the grid and the background selected after.
float voxel(ivec3 i) {
  bool outside = any(lessThan(i, ivec3(0))) || any(greaterThanEqual(i, g_n));
  ivec3 c = clamp(i, ivec3(0), g_n - 1);
  float v = vals[(uint(c.z) * g_ny + uint(c.y)) * g_nx + uint(c.x)];
  return outside ? g_bg : v;
}

float lerp1(float a, float b, float t) {
  precise float r = a + t * (b - a);
  return r;
}

// Trilinear value at a continuous index (FieldView's lerp order: x, then y, then z).
float field(vec3 p) {
  vec3 fl = floor(p);
  ivec3 i = ivec3(fl);
  precise vec3 f = p - fl;
  float c00 = lerp1(voxel(i), voxel(i + ivec3(1, 0, 0)), f.x);
  float c10 = lerp1(voxel(i + ivec3(0, 1, 0)), voxel(i + ivec3(1, 1, 0)), f.x);
  float c01 = lerp1(voxel(i + ivec3(0, 0, 1)), voxel(i + ivec3(1, 0, 1)), f.x);
  float c11 = lerp1(voxel(i + ivec3(0, 1, 1)), voxel(i + ivec3(1, 1, 1)), f.x);
  return lerp1(lerp1(c00, c10, f.y), lerp1(c01, c11, f.y), f.z);
}

float excess(float v) {
  precise float e = g_sign * (v - g_tau);
  return e;
}

vec3 ray_point(vec3 e, vec3 d, float t) {
  precise vec3 p = e + t * d;
  return p;
}

bool inside_at(vec3 e, vec3 d, float t) { return excess(field(ray_point(e, d, t))) > 0.0; }

float lattice_t(float t0, float t1, float h, int k) {
  precise float t = t0 + float(k) * h;
  return min(t, t1);
}

// [ta, tb]: ta outside, tb inside. 8 bisections, then one secant step in the bracket.
float refine(vec3 e, vec3 d, float ta, float tb) {
  for (int i = 0; i < 8; ++i) {
    precise float tm = 0.5 * (ta + tb);
    if (inside_at(e, d, tm)) tb = tm;
    else ta = tm;
  }
  float ea = excess(field(ray_point(e, d, ta)));
  float eb = excess(field(ray_point(e, d, tb)));
  precise float t = 0.5 * (ta + tb);
  if (ea <= 0.0 && eb > 0.0) {
    precise float frac = -ea / (eb - ea);
    t = ta + (tb - ta) * frac;
  }
  return t;
}

// Searches samples k in [kl, kh] for the first inside one; returns its refined t or -1.
float march(vec3 e, vec3 d, float t0, float t1, float h, int kl, int kh) {
  for (int k = kl; k <= kh; ++k) {
    float t = lattice_t(t0, t1, h, k);
    if (inside_at(e, d, t)) return refine(e, d, lattice_t(t0, t1, h, k - 1), t);
  }
  return -1.0;
}

bool range_active(uint b) {
  float mn = brick[2u * b], mx = brick[2u * b + 1u];
  precise float em = g_sign > 0.0 ? mx - g_tau : g_tau - mn;
  return em >= 0.0;
}

bool brick_active(ivec3 c) { return range_active((uint(c.z) * P.by + uint(c.y)) * P.bx + uint(c.x)); }

// Sub-cell ranges follow the brick ranges in binding 2.
bool sub_active(ivec3 s) {
  return range_active(g_sub_base + (uint(s.z) * uint(g_ns.y) + uint(s.y)) * uint(g_ns.x) + uint(s.x));
}

// Parameter of the next brick boundary along one axis, +inf if the ray stays in the
// edge brick (or runs parallel to the axis).
float next_boundary(float e, float d, float inv, int c, int nb) {
  if (d > 0.0 && c + 1 < nb) {
    precise float t = (8.0 * float(c + 1) - e) * inv;
    return t;
  }
  if (d < 0.0 && c > 0) {
    precise float t = (8.0 * float(c) - e) * inv;
    return t;
  }
  return kInf;
}

// The same for sub-cells c in [lo, hi] (one brick's).
float next_sub_boundary(float e, float d, float inv, int c, int lo, int hi) {
  if (d > 0.0 && c < hi) {
    precise float t = (float(SUB) * float(c + 1) - e) * inv;
    return t;
  }
  if (d < 0.0 && c > lo) {
    precise float t = (float(SUB) * float(c) - e) * inv;
    return t;
  }
  return kInf;
}

// Samples k in [kl, kh] (one before [ta, tb] to one after), k >= k_next, in order;
// k_next moves past them. Returns the refined t or -1.
float march_from(vec3 e, vec3 d, float t0, float t1, float h, int K, float ta, float tb, inout int k_next) {
  precise float ra = (ta - t0) / h;
  precise float rb = (tb - t0) / h;
  int kl = max(k_next, int(floor(ra)));
  int kh = min(K, int(ceil(rb)) + 1);
  if (kl > kh) return -1.0;
  float t = march(e, d, t0, t1, h, kl, kh);
  k_next = kh + 1;
  return t;
}

// Second level: the sub-cell DDA through brick c over [tb0, tb1]; samples only in
// sub-cells whose range can hold an inside value (the same lattice as march()).
float walk_subs(vec3 e, vec3 d, float t0, float t1, float h, int K, ivec3 c, float tb0, float tb1,
                inout int k_next) {
  const int per = 8 / SUB;
  vec3 pe = ray_point(e, d, tb0);
  ivec3 lo = per * c;
  ivec3 hi = min(lo + per, g_ns) - 1;
  ivec3 s = clamp(ivec3(floor(pe / float(SUB))), lo, hi);
  float ts0 = tb0;
  for (int step = 0; step < 3 * per + 4; ++step) {
    float tx = next_sub_boundary(e.x, d.x, g_inv_d.x, s.x, lo.x, hi.x);
    float ty = next_sub_boundary(e.y, d.y, g_inv_d.y, s.y, lo.y, hi.y);
    float tz = next_sub_boundary(e.z, d.z, g_inv_d.z, s.z, lo.z, hi.z);
    float ts1 = min(min(min(tx, ty), tz), tb1);
    if (sub_active(s)) {
      float t = march_from(e, d, t0, t1, h, K, ts0, ts1, k_next);
      if (t >= 0.0) return t;
    }
    if (ts1 >= tb1) break;
    if (tx <= ty && tx <= tz) s.x += d.x > 0.0 ? 1 : -1;
    else if (ty <= tz) s.y += d.y > 0.0 ? 1 : -1;
    else s.z += d.z > 0.0 ? 1 : -1;
    ts0 = ts1;
  }
  return -1.0;
}

float walk_bricks(vec3 e, vec3 d, float t0, float t1, float h, int K) {
  ivec3 nb = ivec3(int(P.bx), int(P.by), int(P.bz));
  precise vec3 inv_d = 1.0 / d;  // +-inf on an axis the ray is parallel to (not used there)
  g_inv_d = inv_d;
  vec3 pe = ray_point(e, d, t0);
  ivec3 c = clamp(ivec3(floor(pe / 8.0)), ivec3(0), nb - 1);
  float tb0 = t0;
  int k_next = 1;
  int max_steps = nb.x + nb.y + nb.z + 4;
  for (int s = 0; s < max_steps; ++s) {
    float tx = next_boundary(e.x, d.x, g_inv_d.x, c.x, nb.x);
    float ty = next_boundary(e.y, d.y, g_inv_d.y, c.y, nb.y);
    float tz = next_boundary(e.z, d.z, g_inv_d.z, c.z, nb.z);
    float tb1 = min(min(min(tx, ty), tz), t1);
    if (brick_active(c)) {
      float t = walk_subs(e, d, t0, t1, h, K, c, tb0, tb1, k_next);
      if (t >= 0.0) return t;
    }
    if (tb1 >= t1) break;
    if (tx <= ty && tx <= tz) c.x += d.x > 0.0 ? 1 : -1;
    else if (ty <= tz) c.y += d.y > 0.0 ? 1 : -1;
    else c.z += d.z > 0.0 ? 1 : -1;
    tb0 = tb1;
  }
  return -1.0;
}

// Ray against the box [-1, n] per axis (index space): [tmin, tmax], empty if tmin > tmax.
vec2 box_interval(vec3 e, vec3 d) {
  float tmin = 0.0, tmax = kInf;
  vec3 hi = vec3(float(P.nx), float(P.ny), float(P.nz));
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (e[a] < -1.0 || e[a] > hi[a]) return vec2(1.0, 0.0);
      continue;
    }
    precise float ta = (-1.0 - e[a]) / d[a];
    precise float tb = (hi[a] - e[a]) / d[a];
    tmin = max(tmin, min(ta, tb));
    tmax = min(tmax, max(ta, tb));
  }
  return vec2(tmin, tmax);
}

vec3 dot_safe_normalize(vec3 v) {
  precise float l2 = v.x * v.x + v.y * v.y + v.z * v.z;
  precise vec3 r = v / sqrt(l2);
  return r;
}

// Outward unit normal from central differences (one voxel) of the trilinear field, in
// grid-world (index derivative times 1 / spacing).
vec3 surface_normal(vec3 p) {
  precise vec3 g;
  g.x = (field(p + vec3(1, 0, 0)) - field(p - vec3(1, 0, 0))) * 0.5;
  g.y = (field(p + vec3(0, 1, 0)) - field(p - vec3(0, 1, 0))) * 0.5;
  g.z = (field(p + vec3(0, 0, 1)) - field(p - vec3(0, 0, 1))) * 0.5;
  precise vec3 gw = g * vec3(P.inv_sp_x, P.inv_sp_y, P.inv_sp_z) * (-P.inside_sign);
  precise float l2 = gw.x * gw.x + gw.y * gw.y + gw.z * gw.z;
  if (!(l2 > 0.0)) return vec3(0.0);
  return dot_safe_normalize(gw);
}

// Headlight from the upper left of the camera; two-sided; Lambert + ambient + specular;
// sqrt as display gamma.
vec3 shade(vec3 albedo, vec3 n, vec3 dir) {
  vec3 fwd = vec3(P.fwd_x, P.fwd_y, P.fwd_z), up = vec3(P.up_x, P.up_y, P.up_z);
  vec3 right = vec3(P.right_x, P.right_y, P.right_z);
  precise vec3 lsum = -fwd + 0.5 * up - 0.35 * right;
  vec3 l = dot_safe_normalize(lsum);
  precise float facing = n.x * dir.x + n.y * dir.y + n.z * dir.z;
  vec3 nn = facing > 0.0 ? -n : n;
  precise float lam = max(nn.x * l.x + nn.y * l.y + nn.z * l.z, 0.0);
  precise vec3 hv = l - dir;
  vec3 hn = dot_safe_normalize(hv);
  precise float sp = max(nn.x * hn.x + nn.y * hn.y + nn.z * hn.z, 0.0);
  sp = sp * sp;
  sp = sp * sp;
  sp = sp * sp;
  sp = sp * sp;
  sp = sp * sp;  // ^32
  precise vec3 c = albedo * (0.18 + 0.82 * lam) + vec3(0.25 * sp);
  return c;
}

uint pack_rgba(vec3 c) {
  vec3 g = sqrt(clamp(c, 0.0, 1.0));
  uvec3 u = uvec3(g * 255.0 + 0.5);
  return u.r | (u.g << 8) | (u.b << 16) | (255u << 24);
}

// Primitive intersection in a local frame: origin moved along the ray to the point
// nearest the primitive's centre, lengths divided by the radius (well conditioned in
// float at millimetre sizes and metre distances). Returns (t [m], unit normal) or t < 0.
vec4 intersect_prim(RaycastPrim q, vec3 ro, vec3 rd) {
  vec3 a = vec3(q.ax, q.ay, q.az), b = vec3(q.bx, q.by, q.bz);
  bool two_points = q.kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE || q.kind == ISOTOUCH_RAYCAST_PRIM_CONE;
  precise vec3 centre = two_points ? 0.5 * (a + b) : a;
  precise vec3 oc = centre - ro;
  precise float tc = oc.x * rd.x + oc.y * rd.y + oc.z * rd.z;
  precise vec3 ro2 = ro + tc * rd;
  float s = q.r0;
  precise vec3 al = (a - ro2) / s;
  precise vec3 bl = two_points ? (b - ro2) / s : b;
  precise vec3 cl = (centre - ro2) / s;
  precise float bound = two_points ? 0.5 * length(bl - al) + 1.0 : 1.0;
  if (dot(cl, cl) > bound * bound) return vec4(-1.0);
  precise float tl = -1.0;
  precise vec3 n = vec3(0.0);
  if (q.kind == ISOTOUCH_RAYCAST_PRIM_SPHERE) {
    precise float bb = -dot(al, rd);
    precise float c = dot(al, al) - 1.0;
    precise float h = bb * bb - c;
    if (h < 0.0) return vec4(-1.0);
    tl = -bb - sqrt(h);
    n = tl * rd - al;
  } else if (q.kind == ISOTOUCH_RAYCAST_PRIM_DISC) {
    precise float den = dot(rd, bl);
    if (abs(den) < 1e-6) return vec4(-1.0);
    tl = dot(al, bl) / den;
    precise vec3 r = tl * rd - al;
    if (dot(r, r) > 1.0) return vec4(-1.0);
    n = bl;
  } else if (q.kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE) {
    precise vec3 ba = bl - al, oa = -al;
    precise float baba = dot(ba, ba), bard = dot(ba, rd), baoa = dot(ba, oa);
    precise float rdoa = dot(rd, oa), oaoa = dot(oa, oa);
    precise float qa = baba - bard * bard;
    precise float qb = baba * rdoa - baoa * bard;
    precise float qc = baba * oaoa - baoa * baoa - baba;
    precise float h = qb * qb - qa * qc;
    if (h < 0.0) return vec4(-1.0);
    tl = qa > 0.0 ? (-qb - sqrt(h)) / qa : -1.0;
    precise float y = baoa + tl * bard;
    if (!(qa > 0.0) || y <= 0.0 || y >= baba) {
      precise vec3 o2 = y <= 0.0 ? oa : -bl;
      precise float b2 = dot(rd, o2);
      precise float c2 = dot(o2, o2) - 1.0;
      precise float h2 = b2 * b2 - c2;
      if (h2 <= 0.0) return vec4(-1.0);
      tl = -b2 - sqrt(h2);
    }
    precise vec3 p = tl * rd;
    precise float u = clamp(dot(p - al, ba) / baba, 0.0, 1.0);
    n = p - (al + u * ba);
  } else if (q.kind == ISOTOUCH_RAYCAST_PRIM_CONE) {
    // Capped cone, radius 1 at a, 0 at b (the apex); the base disc closes it.
    precise vec3 ba = bl - al, oa = -al, ob = -bl;
    precise float m0 = dot(ba, ba), m1 = dot(oa, ba), m2 = dot(rd, ba), m3 = dot(rd, oa);
    precise float m5 = dot(oa, oa);
    bool done = false;
    if (m1 < 0.0) {
      precise vec3 w = oa * m2 - rd * m1;
      if (dot(w, w) < m2 * m2) {
        tl = -m1 / m2;
        n = -ba;
        done = true;
      }
    }
    if (!done) {
      precise float hy = m0 + 1.0;
      precise float k2 = m0 * m0 - m2 * m2 * hy;
      precise float k1 = m0 * m0 * m3 - m1 * m2 * hy + m0 * m2;
      precise float k0 = m0 * m0 * m5 - m1 * m1 * hy + m0 * (2.0 * m1 - m0);
      precise float h = k1 * k1 - k2 * k0;
      if (h < 0.0 || k2 == 0.0) return vec4(-1.0);
      tl = (-k1 - sqrt(h)) / k2;
      precise float y = m1 + tl * m2;
      if (y < 0.0 || y > m0) return vec4(-1.0);
      n = m0 * (m0 * (oa + tl * rd) + ba) - ba * hy * y;
    }
  } else {
    return vec4(-1.0);
  }
  precise float t = tc + tl * s;
  if (!(t > 0.0)) return vec4(-1.0);
  return vec4(t, dot_safe_normalize(n));
}

void main() {
  uvec2 px = gl_GlobalInvocationID.xy;
  if (px.x >= P.width || px.y >= P.height) return;
  uint pix = px.y * P.width + px.x;
  g_n = ivec3(int(P.nx), int(P.ny), int(P.nz));
  g_nx = P.nx;
  g_ny = P.ny;
  g_bg = P.background;
  g_tau = P.tau;
  g_sign = P.inside_sign;
  g_ns = (g_n + SUB - 1) / SUB;
  g_sub_base = P.bx * P.by * P.bz;
  vec3 eye = vec3(P.eye_x, P.eye_y, P.eye_z);
  vec3 fwd = vec3(P.fwd_x, P.fwd_y, P.fwd_z), right = vec3(P.right_x, P.right_y, P.right_z);
  vec3 up = vec3(P.up_x, P.up_y, P.up_z);
  precise float sx = (float(px.x) + 0.5) - 0.5 * float(P.width);
  precise float sy = 0.5 * float(P.height) - (float(px.y) + 0.5);
  precise vec3 dsum = fwd * P.focal_px + right * sx + up * sy;
  vec3 dir = dot_safe_normalize(dsum);
  vec3 inv_sp = vec3(P.inv_sp_x, P.inv_sp_y, P.inv_sp_z);
  precise vec3 e = (eye - vec3(P.origin_x, P.origin_y, P.origin_z)) * inv_sp;
  precise vec3 d = dir * inv_sp;

  // The ray's interval in the box and the kept half-space.
  vec2 ti = box_interval(e, d);
  float t0 = ti.x, t1 = ti.y;
  bool cap_entry = false;
  if ((pc.flags & ISOTOUCH_RAYCAST_CLIP) != 0u) {
    vec3 cn = vec3(P.clip_nx, P.clip_ny, P.clip_nz);
    precise float g0 = cn.x * eye.x + cn.y * eye.y + cn.z * eye.z + P.clip_d;
    precise float gd = cn.x * dir.x + cn.y * dir.y + cn.z * dir.z;
    if (gd == 0.0) {
      if (g0 > 0.0) t1 = -1.0;
    } else {
      precise float tp = -g0 / gd;
      if (gd > 0.0) t1 = min(t1, tp);
      else if (tp >= t0) {
        t0 = tp;
        cap_entry = true;
      }
    }
  }

  float t_hit = -1.0;
  bool cap = false;
  if (t0 <= t1) {
    precise float dl = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    precise float h = P.step_vox / dl;
    int K = int(min(ceil((t1 - t0) / h), 1048576.0));
    if (inside_at(e, d, t0)) {
      t_hit = t0;
      cap = cap_entry;
    } else if (K >= 1) {
      t_hit = (pc.flags & ISOTOUCH_RAYCAST_SKIP) != 0u ? walk_bricks(e, d, t0, t1, h, K)
                                                       : march(e, d, t0, t1, h, 1, K);
    }
  }

  vec3 colour = vec3(P.bg_r, P.bg_g, P.bg_b);
  float t_best = kInf;
  if (t_hit >= 0.0) {
    t_best = t_hit;
    if (cap) {
      colour = shade(vec3(P.cap_r, P.cap_g, P.cap_b), vec3(P.clip_nx, P.clip_ny, P.clip_nz), dir);
    } else {
      vec3 n = surface_normal(ray_point(e, d, t_hit));
      colour = shade(vec3(P.surf_r, P.surf_g, P.surf_b), n, dir);
    }
  }
  depth[pix] = t_hit;

  // Overlays: opaque primitives by depth, then translucent ones (and x-ray: opaque
  // primitives hidden behind the surface, shown faintly) blended in order.
  uint np = min(pc.prim_count, ISOTOUCH_RAYCAST_MAX_PRIMS);
  for (uint i = 0u; i < np; ++i) {
    RaycastPrim q = prims[i];
    if (q.alpha < 1.0) continue;
    vec4 r = intersect_prim(q, eye, dir);
    if (r.x > 0.0 && r.x < t_best) {
      t_best = r.x;
      colour = shade(vec3(q.cr, q.cg, q.cb), r.yzw, dir);
    }
  }
  for (uint i = 0u; i < np; ++i) {
    RaycastPrim q = prims[i];
    bool xray = q.pad0 > 0.0;
    if (q.alpha >= 1.0 && !xray) continue;
    vec4 r = intersect_prim(q, eye, dir);
    if (!(r.x > 0.0)) continue;
    float a = r.x < t_best ? q.alpha : (xray ? 0.35 : 0.0);
    if (q.alpha >= 1.0 && r.x <= t_best) a = 0.0;  // drawn in the opaque pass
    if (a > 0.0) colour = mix(colour, shade(vec3(q.cr, q.cg, q.cb), r.yzw, dir), a);
  }
  image[pix] = pack_rgba(colour);
}
