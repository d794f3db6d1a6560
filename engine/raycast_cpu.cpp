// raycast_cpu.cpp - the CPU reference of shaders/raycast.comp: the same float operations
// in the same order (this file is compiled with -ffp-contract=off; the shader marks its
// arithmetic `precise`), one thread.
//
// Where GPU and CPU may differ: floor/ceil/min/max/sqrt and + - * / are exact IEEE on
// both sides on lavapipe (LLVM), so hit distances agree bit for bit there; a GPU whose
// division or sqrt is not correctly rounded (Vulkan allows 2.5 ULP for division) moves a
// sample by an ULP, which can flip the inside test of a sample lying on the isosurface
// and move that pixel's hit by up to one refinement bracket, or change which lattice
// sample is first inside on a grazing ray. Colours use mix() and normalisation in
// orders the GLSL compiler chooses: allow a few 8-bit levels. tests/test_raycast.cpp
// compares depth to 1e-4 voxel on all but 0.1 % of the hit pixels, colour to 3 levels.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "raycast.h"

namespace isotouch::engine {
namespace {

struct F3 {
  float x = 0, y = 0, z = 0;
  float operator[](int a) const { return a == 0 ? x : (a == 1 ? y : z); }
};
F3 operator+(F3 a, F3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
F3 operator-(F3 a, F3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
F3 operator-(F3 a) { return {-a.x, -a.y, -a.z}; }
F3 operator*(F3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
F3 operator*(float s, F3 a) { return {s * a.x, s * a.y, s * a.z}; }
F3 operator*(F3 a, F3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
F3 operator/(F3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
float dot3(F3 a, F3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

constexpr float kInf = std::numeric_limits<float>::infinity();

/// One frame's state: the shader's globals (P, pc, the buffers).
struct Caster {
  const gpu::RaycastParams& P;
  std::uint32_t flags;
  const float* vals;
  const float* brick;
  const float* sub;  ///< sub-cell ranges (RaycastField::sub_minmax)
  const std::vector<gpu::RaycastPrim>& prims;

  // The memory seam (see the shader's voxel()).
  float voxel(int x, int y, int z) const {
    if (x < 0 || y < 0 || z < 0 || x >= int(P.nx) || y >= int(P.ny) || z >= int(P.nz)) return P.background;
    return vals[(std::size_t(std::uint32_t(z)) * P.ny + std::uint32_t(y)) * P.nx + std::uint32_t(x)];
  }
  static float lerp1(float a, float b, float t) { return a + t * (b - a); }
  float field(F3 p) const {
    const F3 fl{std::floor(p.x), std::floor(p.y), std::floor(p.z)};
    const int i = int(fl.x), j = int(fl.y), k = int(fl.z);
    const F3 f = p - fl;
    const float c00 = lerp1(voxel(i, j, k), voxel(i + 1, j, k), f.x);
    const float c10 = lerp1(voxel(i, j + 1, k), voxel(i + 1, j + 1, k), f.x);
    const float c01 = lerp1(voxel(i, j, k + 1), voxel(i + 1, j, k + 1), f.x);
    const float c11 = lerp1(voxel(i, j + 1, k + 1), voxel(i + 1, j + 1, k + 1), f.x);
    return lerp1(lerp1(c00, c10, f.y), lerp1(c01, c11, f.y), f.z);
  }
  float excess(float v) const { return P.inside_sign * (v - P.tau); }
  static F3 ray_point(F3 e, F3 d, float t) { return e + t * d; }
  bool inside_at(F3 e, F3 d, float t) const { return excess(field(ray_point(e, d, t))) > 0.0f; }
  static float lattice_t(float t0, float t1, float h, int k) { return std::min(t0 + float(k) * h, t1); }

  float refine(F3 e, F3 d, float ta, float tb) const {
    for (int i = 0; i < 8; ++i) {
      const float tm = 0.5f * (ta + tb);
      if (inside_at(e, d, tm)) tb = tm;
      else ta = tm;
    }
    const float ea = excess(field(ray_point(e, d, ta)));
    const float eb = excess(field(ray_point(e, d, tb)));
    float t = 0.5f * (ta + tb);
    if (ea <= 0.0f && eb > 0.0f) {
      const float frac = -ea / (eb - ea);
      t = ta + (tb - ta) * frac;
    }
    return t;
  }

  float march(F3 e, F3 d, float t0, float t1, float h, int kl, int kh) const {
    for (int k = kl; k <= kh; ++k) {
      const float t = lattice_t(t0, t1, h, k);
      if (inside_at(e, d, t)) return refine(e, d, lattice_t(t0, t1, h, k - 1), t);
    }
    return -1.0f;
  }

  /// Whether a (min, max) range can hold an inside value.
  bool range_active(const float* r, std::size_t b) const {
    const float mn = r[2 * b], mx = r[2 * b + 1];
    const float em = P.inside_sign > 0.0f ? mx - P.tau : P.tau - mn;
    return em >= 0.0f;
  }
  bool brick_active(int cx, int cy, int cz) const {
    return range_active(brick, (std::size_t(cz) * P.by + std::uint32_t(cy)) * P.bx + std::uint32_t(cx));
  }
  static constexpr int kSub = int(ISOTOUCH_RAYCAST_SUB);
  static int sub_count(std::uint32_t n) { return int((n + ISOTOUCH_RAYCAST_SUB - 1u) / ISOTOUCH_RAYCAST_SUB); }
  bool sub_active(const int s[3]) const {
    const std::size_t sx = std::size_t(sub_count(P.nx)), sy = std::size_t(sub_count(P.ny));
    return range_active(sub, (std::size_t(s[2]) * sy + std::size_t(s[1])) * sx + std::size_t(s[0]));
  }

  static float next_boundary(float e, float d, float inv, int c, int nb) {
    if (d > 0.0f && c + 1 < nb) return (8.0f * float(c + 1) - e) * inv;
    if (d < 0.0f && c > 0) return (8.0f * float(c) - e) * inv;
    return kInf;
  }
  /// The same for sub-cells c in [lo, hi] (one brick's).
  static float next_sub_boundary(float e, float d, float inv, int c, int lo, int hi) {
    if (d > 0.0f && c < hi) return (float(kSub) * float(c + 1) - e) * inv;
    if (d < 0.0f && c > lo) return (float(kSub) * float(c) - e) * inv;
    return kInf;
  }

  /// Samples k in [kl, kh], k >= k_next, in order; k_next moves past them. Returns the refined t or -1.
  float march_from(F3 e, F3 d, float t0, float t1, float h, int K, float ta, float tb, int& k_next) const {
    const int kl = std::max(k_next, int(std::floor((ta - t0) / h)));
    const int kh = std::min(K, int(std::ceil((tb - t0) / h)) + 1);
    if (kl > kh) return -1.0f;
    const float t = march(e, d, t0, t1, h, kl, kh);
    k_next = kh + 1;
    return t;
  }

  /// Second level: the sub-cell DDA through brick c over [tb0, tb1]; samples only in
  /// sub-cells whose range can hold an inside value (the same lattice as march()).
  float walk_subs(F3 e, F3 d, F3 inv_d, float t0, float t1, float h, int K, const int c[3], float tb0, float tb1,
                  int& k_next) const {
    constexpr int per = 8 / kSub;
    const int ns[3] = {sub_count(P.nx), sub_count(P.ny), sub_count(P.nz)};
    const F3 pe = ray_point(e, d, tb0);
    int lo[3], hi[3], s[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = per * c[a];
      hi[a] = std::min(lo[a] + per, ns[a]) - 1;
      s[a] = std::clamp(int(std::floor(pe[a] / float(kSub))), lo[a], hi[a]);
    }
    float ts0 = tb0;
    for (int step = 0; step < 3 * per + 4; ++step) {
      const float tx = next_sub_boundary(e.x, d.x, inv_d.x, s[0], lo[0], hi[0]);
      const float ty = next_sub_boundary(e.y, d.y, inv_d.y, s[1], lo[1], hi[1]);
      const float tz = next_sub_boundary(e.z, d.z, inv_d.z, s[2], lo[2], hi[2]);
      const float ts1 = std::min(std::min(std::min(tx, ty), tz), tb1);
      if (sub_active(s)) {
        const float t = march_from(e, d, t0, t1, h, K, ts0, ts1, k_next);
        if (t >= 0.0f) return t;
      }
      if (ts1 >= tb1) break;
      if (tx <= ty && tx <= tz) s[0] += d.x > 0.0f ? 1 : -1;
      else if (ty <= tz) s[1] += d.y > 0.0f ? 1 : -1;
      else s[2] += d.z > 0.0f ? 1 : -1;
      ts0 = ts1;
    }
    return -1.0f;
  }

  float walk_bricks(F3 e, F3 d, float t0, float t1, float h, int K) const {
    const int nb[3] = {int(P.bx), int(P.by), int(P.bz)};
    const F3 inv_d{1.0f / d.x, 1.0f / d.y, 1.0f / d.z};  // +-inf where d = 0 (not used there)
    const F3 pe = ray_point(e, d, t0);
    int c[3];
    for (int a = 0; a < 3; ++a) c[a] = std::clamp(int(std::floor(pe[a] / 8.0f)), 0, nb[a] - 1);
    float tb0 = t0;
    int k_next = 1;
    const int max_steps = nb[0] + nb[1] + nb[2] + 4;
    for (int s = 0; s < max_steps; ++s) {
      const float tx = next_boundary(e.x, d.x, inv_d.x, c[0], nb[0]);
      const float ty = next_boundary(e.y, d.y, inv_d.y, c[1], nb[1]);
      const float tz = next_boundary(e.z, d.z, inv_d.z, c[2], nb[2]);
      const float tb1 = std::min(std::min(std::min(tx, ty), tz), t1);
      if (brick_active(c[0], c[1], c[2])) {
        const float t = walk_subs(e, d, inv_d, t0, t1, h, K, c, tb0, tb1, k_next);
        if (t >= 0.0f) return t;
      }
      if (tb1 >= t1) break;
      if (tx <= ty && tx <= tz) c[0] += d.x > 0.0f ? 1 : -1;
      else if (ty <= tz) c[1] += d.y > 0.0f ? 1 : -1;
      else c[2] += d.z > 0.0f ? 1 : -1;
      tb0 = tb1;
    }
    return -1.0f;
  }

  void box_interval(F3 e, F3 d, float& tmin, float& tmax) const {
    tmin = 0.0f;
    tmax = kInf;
    const F3 hi{float(P.nx), float(P.ny), float(P.nz)};
    for (int a = 0; a < 3; ++a) {
      if (d[a] == 0.0f) {
        if (e[a] < -1.0f || e[a] > hi[a]) {
          tmin = 1.0f;
          tmax = 0.0f;
          return;
        }
        continue;
      }
      const float ta = (-1.0f - e[a]) / d[a];
      const float tb = (hi[a] - e[a]) / d[a];
      tmin = std::max(tmin, std::min(ta, tb));
      tmax = std::min(tmax, std::max(ta, tb));
    }
  }

  static F3 normalize3(F3 v) {
    const float l2 = v.x * v.x + v.y * v.y + v.z * v.z;
    return v / std::sqrt(l2);
  }

  F3 surface_normal(F3 p) const {
    F3 g;
    g.x = (field(p + F3{1, 0, 0}) - field(p - F3{1, 0, 0})) * 0.5f;
    g.y = (field(p + F3{0, 1, 0}) - field(p - F3{0, 1, 0})) * 0.5f;
    g.z = (field(p + F3{0, 0, 1}) - field(p - F3{0, 0, 1})) * 0.5f;
    const F3 gw = g * F3{P.inv_sp_x, P.inv_sp_y, P.inv_sp_z} * (-P.inside_sign);
    const float l2 = gw.x * gw.x + gw.y * gw.y + gw.z * gw.z;
    if (!(l2 > 0.0f)) return {};
    return normalize3(gw);
  }

  F3 shade(F3 albedo, F3 n, F3 dir) const {
    const F3 fwd{P.fwd_x, P.fwd_y, P.fwd_z}, up{P.up_x, P.up_y, P.up_z}, right{P.right_x, P.right_y, P.right_z};
    const F3 l = normalize3(-fwd + 0.5f * up - 0.35f * right);
    const float facing = n.x * dir.x + n.y * dir.y + n.z * dir.z;
    const F3 nn = facing > 0.0f ? -n : n;
    const float lam = std::max(nn.x * l.x + nn.y * l.y + nn.z * l.z, 0.0f);
    const F3 hn = normalize3(l - dir);
    float sp = std::max(nn.x * hn.x + nn.y * hn.y + nn.z * hn.z, 0.0f);
    for (int i = 0; i < 5; ++i) sp = sp * sp;  // ^32
    const float k = 0.18f + 0.82f * lam;
    const float s = 0.25f * sp;
    return {albedo.x * k + s, albedo.y * k + s, albedo.z * k + s};
  }

  static std::uint32_t pack_rgba(F3 c) {
    auto u = [](float v) { return std::uint32_t(std::sqrt(std::clamp(v, 0.0f, 1.0f)) * 255.0f + 0.5f); };
    return u(c.x) | (u(c.y) << 8) | (u(c.z) << 16) | (255u << 24);
  }

  /// The shader's intersect_prim: t [m] (< 0: miss) and the unit normal.
  static float intersect_prim(const gpu::RaycastPrim& q, F3 ro, F3 rd, F3& normal) {
    const F3 a{q.ax, q.ay, q.az}, b{q.bx, q.by, q.bz};
    const bool two = q.kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE || q.kind == ISOTOUCH_RAYCAST_PRIM_CONE;
    const F3 centre = two ? 0.5f * (a + b) : a;
    const F3 oc = centre - ro;
    const float tc = oc.x * rd.x + oc.y * rd.y + oc.z * rd.z;
    const F3 ro2 = ro + tc * rd;
    const float s = q.r0;
    const F3 al = (a - ro2) / s;
    const F3 bl = two ? (b - ro2) / s : b;
    const F3 cl = (centre - ro2) / s;
    const F3 dl = bl - al;
    const float bound = two ? 0.5f * std::sqrt(dot3(dl, dl)) + 1.0f : 1.0f;
    if (dot3(cl, cl) > bound * bound) return -1.0f;
    float tl = -1.0f;
    F3 n;
    if (q.kind == ISOTOUCH_RAYCAST_PRIM_SPHERE) {
      const float bb = -dot3(al, rd), c = dot3(al, al) - 1.0f, h = bb * bb - c;
      if (h < 0.0f) return -1.0f;
      tl = -bb - std::sqrt(h);
      n = tl * rd - al;
    } else if (q.kind == ISOTOUCH_RAYCAST_PRIM_DISC) {
      const float den = dot3(rd, bl);
      if (std::fabs(den) < 1e-6f) return -1.0f;
      tl = dot3(al, bl) / den;
      const F3 r = tl * rd - al;
      if (dot3(r, r) > 1.0f) return -1.0f;
      n = bl;
    } else if (q.kind == ISOTOUCH_RAYCAST_PRIM_CAPSULE) {
      const F3 ba = bl - al, oa = -al;
      const float baba = dot3(ba, ba), bard = dot3(ba, rd), baoa = dot3(ba, oa);
      const float rdoa = dot3(rd, oa), oaoa = dot3(oa, oa);
      const float qa = baba - bard * bard, qb = baba * rdoa - baoa * bard, qc = baba * oaoa - baoa * baoa - baba;
      const float h = qb * qb - qa * qc;
      if (h < 0.0f) return -1.0f;
      tl = qa > 0.0f ? (-qb - std::sqrt(h)) / qa : -1.0f;
      const float y = baoa + tl * bard;
      if (!(qa > 0.0f) || y <= 0.0f || y >= baba) {
        const F3 o2 = y <= 0.0f ? oa : -bl;
        const float b2 = dot3(rd, o2), c2 = dot3(o2, o2) - 1.0f, h2 = b2 * b2 - c2;
        if (h2 <= 0.0f) return -1.0f;
        tl = -b2 - std::sqrt(h2);
      }
      const F3 p = tl * rd;
      const float u = std::clamp(dot3(p - al, ba) / baba, 0.0f, 1.0f);
      n = p - (al + u * ba);
    } else if (q.kind == ISOTOUCH_RAYCAST_PRIM_CONE) {
      const F3 ba = bl - al, oa = -al;
      const float m0 = dot3(ba, ba), m1 = dot3(oa, ba), m2 = dot3(rd, ba), m3 = dot3(rd, oa), m5 = dot3(oa, oa);
      bool done = false;
      if (m1 < 0.0f) {
        const F3 w = oa * m2 - rd * m1;
        if (dot3(w, w) < m2 * m2) {
          tl = -m1 / m2;
          n = -ba;
          done = true;
        }
      }
      if (!done) {
        const float hy = m0 + 1.0f;
        const float k2 = m0 * m0 - m2 * m2 * hy;
        const float k1 = m0 * m0 * m3 - m1 * m2 * hy + m0 * m2;
        const float k0 = m0 * m0 * m5 - m1 * m1 * hy + m0 * (2.0f * m1 - m0);
        const float h = k1 * k1 - k2 * k0;
        if (h < 0.0f || k2 == 0.0f) return -1.0f;
        tl = (-k1 - std::sqrt(h)) / k2;
        const float y = m1 + tl * m2;
        if (y < 0.0f || y > m0) return -1.0f;
        n = m0 * (m0 * (oa + tl * rd) + ba) - ba * hy * y;
      }
    } else {
      return -1.0f;
    }
    const float t = tc + tl * s;
    if (!(t > 0.0f)) return -1.0f;
    normal = normalize3(n);
    return t;
  }

  static F3 mix3(F3 x, F3 y, float a) { return x * (1.0f - a) + y * a; }

  void pixel(std::uint32_t px, std::uint32_t py, std::uint32_t& rgba, float& depth_out) const {
    const F3 eye{P.eye_x, P.eye_y, P.eye_z}, fwd{P.fwd_x, P.fwd_y, P.fwd_z};
    const F3 right{P.right_x, P.right_y, P.right_z}, up{P.up_x, P.up_y, P.up_z};
    const float sx = (float(px) + 0.5f) - 0.5f * float(P.width);
    const float sy = 0.5f * float(P.height) - (float(py) + 0.5f);
    const F3 dir = normalize3(fwd * P.focal_px + right * sx + up * sy);
    const F3 inv_sp{P.inv_sp_x, P.inv_sp_y, P.inv_sp_z};
    const F3 e = (eye - F3{P.origin_x, P.origin_y, P.origin_z}) * inv_sp;
    const F3 d = dir * inv_sp;

    float t0, t1;
    box_interval(e, d, t0, t1);
    bool cap_entry = false;
    if (flags & ISOTOUCH_RAYCAST_CLIP) {
      const F3 cn{P.clip_nx, P.clip_ny, P.clip_nz};
      const float g0 = cn.x * eye.x + cn.y * eye.y + cn.z * eye.z + P.clip_d;
      const float gd = cn.x * dir.x + cn.y * dir.y + cn.z * dir.z;
      if (gd == 0.0f) {
        if (g0 > 0.0f) t1 = -1.0f;
      } else {
        const float tp = -g0 / gd;
        if (gd > 0.0f) t1 = std::min(t1, tp);
        else if (tp >= t0) {
          t0 = tp;
          cap_entry = true;
        }
      }
    }

    float t_hit = -1.0f;
    bool cap = false;
    if (t0 <= t1) {
      const float dl = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
      const float h = P.step_vox / dl;
      const int K = int(std::min(std::ceil((t1 - t0) / h), 1048576.0f));
      if (inside_at(e, d, t0)) {
        t_hit = t0;
        cap = cap_entry;
      } else if (K >= 1) {
        t_hit = (flags & ISOTOUCH_RAYCAST_SKIP) ? walk_bricks(e, d, t0, t1, h, K) : march(e, d, t0, t1, h, 1, K);
      }
    }

    F3 colour{P.bg_r, P.bg_g, P.bg_b};
    float t_best = kInf;
    if (t_hit >= 0.0f) {
      t_best = t_hit;
      if (cap) colour = shade({P.cap_r, P.cap_g, P.cap_b}, {P.clip_nx, P.clip_ny, P.clip_nz}, dir);
      else colour = shade({P.surf_r, P.surf_g, P.surf_b}, surface_normal(ray_point(e, d, t_hit)), dir);
    }
    depth_out = t_hit;

    const std::size_t np = std::min<std::size_t>(prims.size(), ISOTOUCH_RAYCAST_MAX_PRIMS);
    for (std::size_t i = 0; i < np; ++i) {
      const gpu::RaycastPrim& q = prims[i];
      if (q.alpha < 1.0f) continue;
      F3 n;
      const float t = intersect_prim(q, eye, dir, n);
      if (t > 0.0f && t < t_best) {
        t_best = t;
        colour = shade({q.cr, q.cg, q.cb}, n, dir);
      }
    }
    for (std::size_t i = 0; i < np; ++i) {
      const gpu::RaycastPrim& q = prims[i];
      const bool xray = q.pad0 > 0.0f;
      if (q.alpha >= 1.0f && !xray) continue;
      F3 n;
      const float t = intersect_prim(q, eye, dir, n);
      if (!(t > 0.0f)) continue;
      float a = t < t_best ? q.alpha : (xray ? 0.35f : 0.0f);
      if (q.alpha >= 1.0f && t <= t_best) a = 0.0f;
      if (a > 0.0f) colour = mix3(colour, shade({q.cr, q.cg, q.cb}, n, dir), a);
    }
    rgba = pack_rgba(colour);
  }
};

}  // namespace

RaycastImage render_cpu(const RaycastField& field, const CameraView& view, const RaycastStyle& style, int width,
                        int height, const std::vector<gpu::RaycastPrim>& prims) {
  const auto c0 = std::chrono::steady_clock::now();
  const gpu::RaycastParams P = make_params(field, view, style, width, height);
  const Caster c{P, style_flags(style), field.values.data(), field.brick_minmax.data(), field.sub_minmax.data(), prims};
  RaycastImage img;
  img.width = width;
  img.height = height;
  img.rgba.resize(std::size_t(width) * std::size_t(height));
  img.depth.resize(img.rgba.size());
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const std::size_t i = std::size_t(y) * std::size_t(width) + std::size_t(x);
      c.pixel(std::uint32_t(x), std::uint32_t(y), img.rgba[i], img.depth[i]);
    }
  img.submit_wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - c0).count();
  return img;
}

}  // namespace isotouch::engine
