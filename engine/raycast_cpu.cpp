// raycast_cpu.cpp - the CPU reference of shaders/raycast_common.glsl and the raycast_*.comp passes: the same float operations
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
#include <stdexcept>

#include "isotouch/engine/raycast.h"

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
/// Bisections of the refinement, as the shader's (shaders/isotouch_shared.h).
constexpr int kBisections = int(ISOTOUCH_RAYCAST_BISECTIONS);

/// One frame's state: the shader's globals (P, pc, the buffers).
struct Caster {
  const gpu::RaycastParams& P;
  std::uint32_t flags;
  const float* vals;
  const std::uint8_t* cells;  ///< cell distances (RaycastField::cell_dist)
  const std::vector<gpu::RaycastPrim>& prims;

  // The memory seam (see the shader's voxel()).
  float voxel(int x, int y, int z) const {
    if (x < 0 || y < 0 || z < 0 || x >= int(P.nx) || y >= int(P.ny) || z >= int(P.nz)) return P.background;
    return vals[(std::size_t(std::uint32_t(z)) * P.ny + std::uint32_t(y)) * P.nx + std::uint32_t(x)];
  }
  static float lerp1(float a, float b, float t) { return a + t * (b - a); }
  /// The trilinear value at fractions f of the cell with lower corner (i, j, k): lerps along
  /// x, then y, then z (the shader's trilerp).
  float cell_value(int i, int j, int k, F3 f) const {
    const float c00 = lerp1(voxel(i, j, k), voxel(i + 1, j, k), f.x);
    const float c10 = lerp1(voxel(i, j + 1, k), voxel(i + 1, j + 1, k), f.x);
    const float c01 = lerp1(voxel(i, j, k + 1), voxel(i + 1, j, k + 1), f.x);
    const float c11 = lerp1(voxel(i, j + 1, k + 1), voxel(i + 1, j + 1, k + 1), f.x);
    return lerp1(lerp1(c00, c10, f.y), lerp1(c01, c11, f.y), f.z);
  }
  float field(F3 p) const {
    const F3 fl{std::floor(p.x), std::floor(p.y), std::floor(p.z)};
    return cell_value(int(fl.x), int(fl.y), int(fl.z), p - fl);
  }
  float excess(float v) const { return P.inside_sign * (v - P.tau); }
  static F3 ray_point(F3 e, F3 d, float t) { return e + t * d; }
  bool inside_at(F3 e, F3 d, float t) const { return excess(field(ray_point(e, d, t))) > 0.0f; }
  static float lattice_t(float t0, float t1, float h, int k) { return std::min(t0 + float(k) * h, t1); }

  /// The shader's refine(): the excess at both ends, kBisections bisections keeping the
  /// excess at the bracket's ends, the secant point of the last bracket.
  float refine(F3 e, F3 d, float ta, float tb) const {
    float ea = excess(field(ray_point(e, d, ta)));
    float eb = excess(field(ray_point(e, d, tb)));
    for (int i = 0; i < kBisections; ++i) {
      const float tm = 0.5f * (ta + tb);
      const float em = excess(field(ray_point(e, d, tm)));
      if (em > 0.0f) {
        tb = tm;
        eb = em;
      } else {
        ta = tm;
        ea = em;
      }
    }
    float t = 0.5f * (ta + tb);
    if (ea <= 0.0f && eb > 0.0f) {
      const float frac = -ea / (eb - ea);
      t = ta + (tb - ta) * frac;
    }
    return std::clamp(t, ta, tb);  // the shader's clamp (its normal reads a block around the bracket)
  }

  /// The plain march: the first inside sample k in [1, K], or 0 (the caller refines).
  int march(F3 e, F3 d, float t0, float t1, float h, int K) const {
    for (int k = 1; k <= K; ++k)
      if (inside_at(e, d, lattice_t(t0, t1, h, k))) return k;
    return 0;
  }

  /// The byte of trilinear cell c (lower corner, in [-1, n] per axis; see the shader).
  unsigned cell_dist(int x, int y, int z) const {
    const std::size_t cx = std::size_t(P.nx) + 2, cy = std::size_t(P.ny) + 2;
    return cells[(std::size_t(z + 1) * cy + std::size_t(y + 1)) * cx + std::size_t(x + 1)];
  }

  /// The shader's march_skip: the same lattice, inactive cells not evaluated, jumps past
  /// the box of cells within D - 1 of an inactive cell at distance D.
  int march_skip(F3 e, F3 d, F3 inv_d, float t0, float t1, float h, int K, float eps) const {
    int k = 1;
    while (k <= K) {
      const float t = lattice_t(t0, t1, h, k);
      const F3 p = ray_point(e, d, t);
      const F3 fl{std::floor(p.x), std::floor(p.y), std::floor(p.z)};
      const int c[3] = {int(fl.x), int(fl.y), int(fl.z)};
      const int n[3] = {int(P.nx), int(P.ny), int(P.nz)};
      bool in_cells = true;
      for (int a = 0; a < 3; ++a) in_cells = in_cells && c[a] >= -1 && c[a] <= n[a];
      const unsigned D = in_cells ? cell_dist(c[0], c[1], c[2]) : 0u;
      if (D == 0u) {
        if (excess(field(p)) > 0.0f) return k;
        ++k;
      } else {
        const float r = float(D) - eps;
        float tp[3];
        for (int a = 0; a < 3; ++a) {
          const float plane = d[a] > 0.0f ? fl[a] + r : fl[a] - (r - 1.0f);
          tp[a] = d[a] == 0.0f ? kInf : (plane - e[a]) * inv_d[a];
        }
        const float t_exit = std::min(std::min(tp[0], tp[1]), tp[2]);
        const float kr = (t_exit - t0) / h;
        k = std::max(k + 1, int(std::min(std::ceil(kr), float(K + 1))));
      }
    }
    return 0;
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

  /// The shader's surface_normal: per axis, the trilinear interpolation at p's fractions of
  /// the cells one voxel up and down (field(p +- e_a) but for rounding), halved difference.
  F3 surface_normal(F3 p) const {
    const F3 fl{std::floor(p.x), std::floor(p.y), std::floor(p.z)};
    const int i = int(fl.x), j = int(fl.y), k = int(fl.z);
    const F3 f = p - fl;
    auto at = [&](int ox, int oy, int oz) { return cell_value(i + ox, j + oy, k + oz, f); };
    F3 g;
    g.x = (at(1, 0, 0) - at(-1, 0, 0)) * 0.5f;
    g.y = (at(0, 1, 0) - at(0, -1, 0)) * 0.5f;
    g.z = (at(0, 0, 1) - at(0, 0, -1)) * 0.5f;
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

  static std::uint32_t pack_rgba(F3 c) { return pack_rgba8(c.x, c.y, c.z); }

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
      const int K = int(std::min(std::ceil((t1 - t0) / h), float(ISOTOUCH_RAYCAST_MAX_SAMPLES)));
      // Sample 0; with skipping, not evaluated where its cell is inactive (the shader's rule).
      const bool skip = (flags & ISOTOUCH_RAYCAST_SKIP) != 0u;
      const F3 p0 = ray_point(e, d, t0);
      const int c0[3] = {int(std::floor(p0.x)), int(std::floor(p0.y)), int(std::floor(p0.z))};
      bool in_cells = true;
      for (int a = 0; a < 3; ++a) in_cells = in_cells && c0[a] >= -1 && c0[a] <= int(a == 0 ? P.nx : a == 1 ? P.ny : P.nz);
      const bool need0 = !skip || !in_cells || cell_dist(c0[0], c0[1], c0[2]) == 0u;
      if (need0 && excess(field(p0)) > 0.0f) {
        t_hit = t0;
        cap = cap_entry;
      }
      int k_hit = 0;
      if (!(t_hit >= 0.0f) && K >= 1) {
        if (skip) {
          const F3 inv_d{1.0f / d.x, 1.0f / d.y, 1.0f / d.z};
          const float mag = std::max(std::max(std::max(std::fabs(e.x), std::fabs(e.y)), std::fabs(e.z)),
                                     std::max(std::max(float(P.nx), float(P.ny)), float(P.nz)));
          const float eps = 0.03125f + 4e-6f * (mag + t1 * dl);
          k_hit = march_skip(e, d, inv_d, t0, t1, h, K, eps);
        } else {
          k_hit = march(e, d, t0, t1, h, K);
        }
      }
      if (k_hit > 0) t_hit = refine(e, d, lattice_t(t0, t1, h, k_hit - 1), lattice_t(t0, t1, h, k_hit));
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

std::uint32_t pack_rgba8(float r, float g, float b) {
  auto u = [](float v) { return std::uint32_t(std::sqrt(std::clamp(v, 0.0f, 1.0f)) * 255.0f + 0.5f); };
  return u(r) | (u(g) << 8) | (u(b) << 16) | (255u << 24);
}

RaycastImage render_cpu(const RaycastField& field, const CameraView& view, const RaycastStyle& style, int width,
                        int height, const std::vector<gpu::RaycastPrim>& prims) {
  const auto c0 = std::chrono::steady_clock::now();
  const gpu::RaycastParams P = make_params(field, view, style, width, height);
  if (field.cell_dist.size() != std::size_t(P.nx + 2) * (P.ny + 2) * (P.nz + 2))
    throw std::invalid_argument("raycast: the field has no cell distances for its grid (build it with make_raycast_field)");
  const Caster c{P, style_flags(style), field.values.data(), field.cell_dist.data(), prims};
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
