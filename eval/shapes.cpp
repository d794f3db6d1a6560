#include "isotouch/eval/shapes.h"

#include <algorithm>
#include <cmath>

namespace isotouch::eval {
using core::Vec3;
using engine::Volume;
using engine::VolumeError;
namespace {

using core::Vec3;
constexpr double kH = 1e-3;  // voxel [m]
constexpr int kN = 64;

Volume grid_volume(const std::string& name) {
  Volume v;
  v.grid.dims = {kN, kN, kN};
  v.grid.spacing_m = {kH, kH, kH};
  v.grid.origin_m = {0, 0, 0};
  v.voxels.resize(v.grid.voxel_count());
  v.path = "synthetic:" + name;
  v.reader = "synthetic";
  v.component_type = "float";
  return v;
}

template <class F>
void fill(Volume& v, F&& value) {
  for (int z = 0; z < kN; ++z)
    for (int y = 0; y < kN; ++y)
      for (int x = 0; x < kN; ++x)
        v.voxels[v.grid.index(x, y, z)] = float(value(v.grid.to_world({double(x), double(y), double(z)})));
  v.update_stats();
}

class SphereShape final : public Shape {
 public:
  SphereShape(Vec3 c, double r) : c_(c), r_(r) {}
  void closest(const Vec3& x, Vec3& p, Vec3& n) const override {
    n = core::normalized_or(x - c_, {0, 0, 1});
    p = c_ + n * r_;
  }
  double depth(const Vec3& x) const override { return r_ - core::norm(x - c_); }

 private:
  Vec3 c_;
  double r_;
};

class BoxShape final : public Shape {
 public:
  BoxShape(Vec3 c, Vec3 half) : c_(c), h_(half) {}
  double depth(const Vec3& x) const override {
    const Vec3 q{std::abs(x.x - c_.x) - h_.x, std::abs(x.y - c_.y) - h_.y, std::abs(x.z - c_.z) - h_.z};
    const Vec3 o{std::max(q.x, 0.0), std::max(q.y, 0.0), std::max(q.z, 0.0)};
    return -(core::norm(o) + std::min(std::max({q.x, q.y, q.z}), 0.0));
  }
  void closest(const Vec3& x, Vec3& p, Vec3& n) const override {
    const Vec3 d = x - c_;
    const double a[3] = {d.x, d.y, d.z}, h[3] = {h_.x, h_.y, h_.z};
    double out[3];
    bool inside = true;
    for (int i = 0; i < 3; ++i) {
      out[i] = std::clamp(a[i], -h[i], h[i]);
      if (std::abs(a[i]) > h[i]) inside = false;
    }
    if (inside) {  // push to the nearest face
      int best = 0;
      double gap = 1e300;
      for (int i = 0; i < 3; ++i)
        if (h[i] - std::abs(a[i]) < gap) {
          gap = h[i] - std::abs(a[i]);
          best = i;
        }
      out[best] = a[best] >= 0 ? h[best] : -h[best];
      double nn[3] = {0, 0, 0};
      nn[best] = a[best] >= 0 ? 1 : -1;
      n = {nn[0], nn[1], nn[2]};
    } else {
      const Vec3 cp{out[0], out[1], out[2]};
      n = core::normalized_or(d - cp, {0, 0, 1});
    }
    p = c_ + Vec3{out[0], out[1], out[2]};
  }

 private:
  Vec3 c_, h_;
};

class SpheresShape final : public Shape {
 public:
  explicit SpheresShape(std::vector<SphereShape> s) : s_(std::move(s)) {}
  double depth(const Vec3& x) const override {
    double d = -1e300;
    for (const auto& s : s_) d = std::max(d, s.depth(x));
    return d;
  }
  void closest(const Vec3& x, Vec3& p, Vec3& n) const override {
    double best = -1e300;
    for (const auto& s : s_) {
      const double d = s.depth(x);
      if (d > best) {
        best = d;
        s.closest(x, p, n);
      }
    }
  }

 private:
  std::vector<SphereShape> s_;
};

class KnotTube final : public Shape {
 public:
  KnotTube(Vec3 c, double R, double r, double a) : c_(c), R_(R), r_(r), a_(a) {
    for (int i = 0; i < kSamples; ++i) pts_[i] = curve(2 * M_PI * i / kSamples);
  }
  Vec3 curve(double t) const {
    const double rho = R_ + r_ * std::cos(3 * t);
    return c_ + Vec3{rho * std::cos(2 * t), rho * std::sin(2 * t), r_ * std::sin(3 * t)};
  }
  Vec3 d1(double t) const {
    const double rho = R_ + r_ * std::cos(3 * t), drho = -3 * r_ * std::sin(3 * t);
    return {drho * std::cos(2 * t) - 2 * rho * std::sin(2 * t), drho * std::sin(2 * t) + 2 * rho * std::cos(2 * t),
            3 * r_ * std::cos(3 * t)};
  }
  Vec3 d2(double t) const {
    const double rho = R_ + r_ * std::cos(3 * t), drho = -3 * r_ * std::sin(3 * t), ddrho = -9 * r_ * std::cos(3 * t);
    return {ddrho * std::cos(2 * t) - 4 * drho * std::sin(2 * t) - 4 * rho * std::cos(2 * t),
            ddrho * std::sin(2 * t) + 4 * drho * std::cos(2 * t) - 4 * rho * std::sin(2 * t), -9 * r_ * std::sin(3 * t)};
  }
  /// Closest point on the centre curve to x.
  Vec3 on_curve(const Vec3& x) const {
    int bi = 0;
    double bd = 1e300;
    for (int i = 0; i < kSamples; ++i) {
      const Vec3 d = pts_[i] - x;
      const double dd = core::dot(d, d);
      if (dd < bd) {
        bd = dd;
        bi = i;
      }
    }
    double t = 2 * M_PI * bi / kSamples;
    const double dt = 2 * M_PI / kSamples;
    for (int k = 0; k < 8; ++k) {  // Newton on g(t) = (C - x) . C'
      const Vec3 e = curve(t) - x, c1 = d1(t);
      const double g = core::dot(e, c1), gp = core::dot(c1, c1) + core::dot(e, d2(t));
      if (!(gp > 0)) break;
      const double step = std::clamp(g / gp, -dt, dt);
      t -= step;
      if (std::abs(step) * core::norm(c1) < 1e-10) break;
    }
    return curve(t);
  }
  double depth(const Vec3& x) const override { return a_ - core::norm(x - on_curve(x)); }
  void closest(const Vec3& x, Vec3& p, Vec3& n) const override {
    const Vec3 c = on_curve(x);
    n = core::normalized_or(x - c, {0, 0, 1});
    p = c + n * a_;
  }

 private:
  static constexpr int kSamples = 512;
  Vec3 c_;
  double R_, r_, a_;
  Vec3 pts_[kSamples];
};

}  // namespace

std::vector<std::string> synthetic_scene_names() { return {"sphere", "box", "three-spheres", "knot"}; }

SyntheticScene make_synthetic_scene(const std::string& name) {
  SyntheticScene s;
  s.name = name;
  s.volume = grid_volume(name);
  const Vec3 centre = s.volume.grid.centre_m();
  sim::ScriptParams& sp = s.script;
  sp.approach_distance_m = 0.006;
  sp.approach_speed_m_s = 0.02;
  sp.press_depth_m = 0.003;
  sp.press_speed_m_s = 0.01;
  sp.hold_s = 0.1;
  sp.stroke_length_m = 0.016;
  sp.stroke_speed_m_s = 0.02;
  sp.rest_s = 0.05;
  if (name == "sphere") {
    auto shape = std::make_unique<SphereShape>(centre, 20 * kH);
    fill(s.volume, [&](const Vec3& x) { return shape->depth(x) * 1000; });
    s.truth = std::move(shape);
    sp.ray_origin_frac = {0.5, 0.5, 1.2};
    sp.ray_direction = {0, 0, -1};
    sp.stroke_direction = {1, 0.3, 0};
    s.description = "sphere of radius 20 voxels in 64^3, signed distance [mm], tau = 0";
  } else if (name == "box") {
    auto shape = std::make_unique<BoxShape>(centre + Vec3{0.3, 0.2, 0.1} * kH, Vec3{16, 12, 9} * kH);
    fill(s.volume, [&](const Vec3& x) { return shape->depth(x) * 1000; });
    s.truth = std::move(shape);
    sp.ray_origin_frac = {0.55, 0.5, 1.2};
    sp.ray_direction = {0, 0, -1};
    sp.stroke_direction = {1, 0, 0};
    sp.stroke_length_m = 0.020;  // over the edge at x = 47.8 mm
    s.description = "box 32 x 24 x 18 voxels in 64^3, off-grid centre, signed distance [mm], tau = 0";
  } else if (name == "three-spheres") {
    const double dens[3] = {150, 300, 600}, R = 9 * kH, w = 4 * kH;
    const Vec3 cs[3] = {centre + Vec3{-14, -11, 0} * kH, centre + Vec3{13, -10, 4} * kH, centre + Vec3{0, 12, -5} * kH};
    s.tau = 100;
    fill(s.volume, [&](const Vec3& x) {
      double v = 0;
      for (int i = 0; i < 3; ++i)
        v = std::max(v, dens[i] * std::clamp(0.5 + (R - core::norm(x - cs[i])) / w, 0.0, 1.0));
      return v;
    });
    std::vector<SphereShape> spheres;
    for (int i = 0; i < 3; ++i) spheres.emplace_back(cs[i], R + w * (0.5 - s.tau / dens[i]));
    s.truth = std::make_unique<SpheresShape>(std::move(spheres));
    // Come down on the densest sphere (isosurface radius 9 + 4/3 voxels).
    sp.ray_origin_frac = {(cs[2].x - 0.0015) / (63 * kH), cs[2].y / (63 * kH), 1.2};
    sp.ray_direction = {0, 0, -1};
    sp.stroke_direction = {0, 1, 0};
    sp.stroke_length_m = 0.010;
    s.description = "three spheres (radius 9 voxels, densities 150/300/600, 4-voxel edge ramp), tau = 100";
  } else if (name == "knot") {
    auto shape = std::make_unique<KnotTube>(centre, 14 * kH, 8 * kH, 3.5 * kH);
    fill(s.volume, [&](const Vec3& x) { return shape->depth(x) * 1000; });
    // Prescribed stroke along the concave side of the inner strand where the centre line
    // bends hardest (t = pi, radius of curvature 15 voxels): start on the side facing the
    // centre of curvature, then carry that side along with a rotation-minimizing frame
    // so the HIP moves along the centre line (concave there), not around the tube.
    const double a = 3.5 * kH, t0 = M_PI - 0.2, t1 = M_PI + 0.2, depth = 0.0005;
    auto tangent = [&](double t) { return core::normalized_or(shape->d1(t), {0, 1, 0}); };
    const Vec3 c1 = shape->d1(t0), c2 = shape->d2(t0);
    Vec3 side = core::normalized_or(c2 - c1 * (core::dot(c2, c1) / core::dot(c1, c1)), {1, 0, 0});
    const Vec3 start = shape->curve(t0) + side * (a + 0.002);
    const Vec3 in0 = shape->curve(t0) + side * (a - depth);
    for (int k = 0; k < 50; ++k) s.hip_path.push_back(start);
    for (int k = 0; k <= 200; ++k) s.hip_path.push_back(start + (in0 - start) * (k / 200.0));
    s.slide_begin = s.hip_path.size();
    for (int k = 1; k <= 250; ++k) {  // 10.7 mm in 0.25 s
      const double t = t0 + (t1 - t0) * k / 250.0;
      const Vec3 tg = tangent(t);
      side = core::normalized_or(side - tg * core::dot(side, tg), side);
      s.hip_path.push_back(shape->curve(t) + side * (a - depth));
    }
    s.slide_end = s.hip_path.size();
    const Vec3 end = s.hip_path.back(), out = shape->curve(t1) + side * (a + 0.002);
    for (int k = 1; k <= 200; ++k) s.hip_path.push_back(end + (out - end) * (k / 200.0));
    s.truth = std::move(shape);
    // For `isotouch run`: into the gap between strands, onto the side of the inner strand
    // that faces the centre of curvature of the centre line at t = pi.
    sp.ray_origin_frac = {(31.5 + 12.0) / 63.0, 0.5, 0.5};
    sp.ray_direction = {-1, 0, 0};
    sp.stroke_direction = {0, 12, -24};  // C'(pi)
    sp.approach_distance_m = 0.003;
    sp.press_depth_m = 0.002;
    sp.stroke_length_m = 0.010;
    sp.stroke_speed_m_s = 0.03;
    s.description = "tube of radius 3.5 voxels around a (2,3) torus knot (R = 14, r = 8 voxels) in 64^3, distance [mm], tau = 0; prescribed fast stroke (43 mm/s) along the concave side";
  } else {
    throw VolumeError("synthetic:" + name + ": unknown synthetic scene (known: sphere, box, three-spheres, knot)");
  }
  return s;
}

}  // namespace isotouch::eval
