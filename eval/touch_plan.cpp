#include "isotouch/eval/touch_plan.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "isotouch/core/isosurface.h"
#include "isotouch/eval/surface_distance.h"
#include "isotouch/servo/sampling.h"

namespace isotouch::eval {
namespace {
using core::Vec3;

// Most stroke steps, whatever the grid (as the ray script).
constexpr long kMaxStrokeSteps = 10000;
// Stroke directions tried around the normal, and the score (a share of the force's depth)
// at which the scene's own direction is kept without trying the others.
constexpr int kDirections = 8;
constexpr double kGoodEnough = 0.5;
// Where the ray's contact holds no stroke that good: other starts, every kStartEvery stroke
// steps along walks of kStartReach [m] from it in each direction.
constexpr double kStartReach = 0.012;
constexpr std::size_t kStartEvery = 6;
// The planner's cost whatever the grid (a 0.05 mm micro-CT would otherwise take hours): each
// march at most kMaxMarch samples, at most kMaxWallChecks wall checks a stroke (evenly
// spread), at most kMaxStarts other starts a direction.
constexpr double kMaxMarch = 1024;
constexpr std::size_t kMaxWallChecks = 256;
constexpr std::size_t kMaxStarts = 8;
// Where no start within kStartReach holds a good stroke either (a thin rib under the ray):
// the first contacts of rays parallel to the scene's, from a kFarGrid x kFarGrid grid over
// the middle of the box (fractions kFarLo..kFarHi across it).
constexpr int kFarGrid = 5;
constexpr double kFarLo = 0.2, kFarHi = 0.8;

double smallest_spacing(const core::Grid& g) { return std::min({g.spacing_m.x, g.spacing_m.y, g.spacing_m.z}); }

/// The outward unit normal of the isosurface at `p` (the trilinear gradient), or `fallback`
/// where the gradient vanishes.
Vec3 outward_normal(const core::SampleField& f, const core::Isosurface& iso, const Vec3& p, const Vec3& fallback) {
  return core::normalized_or(iso.outward(servo::sample_trilinear(f, p).gradient), fallback);
}

/// True where `p` lies in the grid's box (beyond it is no object, only the box's edge).
bool in_box(const core::Grid& g, const Vec3& p) {
  const Vec3 i = g.to_index(p);
  return i.x >= 0 && i.y >= 0 && i.z >= 0 && i.x <= g.dims[0] - 1 && i.y <= g.dims[1] - 1 && i.z <= g.dims[2] - 1;
}

/// The wall's thickness under surface point `s` along -n: from s to where the line leaves the
/// object after having entered it (within a voxel of s), marched in quarter voxels up to
/// `reach` [m] and bisected; +inf if still inside there or if the line leaves the box first;
/// 0 if it never enters within a voxel of s (the normal does not lead into the object).
double thickness_under(const core::SampleField& f, const core::Isosurface& iso, const Vec3& s, const Vec3& n,
                       double reach) {
  const double h = std::max(0.25 * smallest_spacing(f.grid), reach / kMaxMarch);
  const auto inside = [&](double t) { return iso.contains(servo::sample_value(f, s - n * t)); };
  bool entered = false;
  for (double t = h; t <= reach; t += h) {
    if (!in_box(f.grid, s - n * t)) break;
    if (inside(t)) {
      entered = true;
    } else if (entered) {
      double lo = t - h, hi = t;
      for (int k = 0; k < 40; ++k) (inside(0.5 * (lo + hi)) ? lo : hi) = 0.5 * (lo + hi);
      return 0.5 * (lo + hi);
    } else if (t > 4 * h) {
      return 0.0;  // -n does not lead into the object here: no press can be judged safe
    }
  }
  return std::numeric_limits<double>::infinity();
}

/// The stroke's surface points: walk from the contact along `tangent` in steps `ds`, each
/// step projected onto the nearest isosurface point and the tangent carried over to the new
/// tangent plane. Stops where no surface is found within two steps or the walk stalls.
void walk_stroke(const core::SampleField& f, const core::Isosurface& iso, Vec3 tangent, double length, TouchPlan& plan) {
  const double h = smallest_spacing(f.grid);
  const double ds = std::max(0.5 * h, length / double(kMaxStrokeSteps));
  const long steps = length > 0 ? std::max(1L, long(std::ceil(length / ds))) : 0;
  SurfaceDistanceOptions opt;
  opt.max_radius_m = 2.0 * ds + h;
  for (long i = 1; i <= steps; ++i) {
    const Vec3 s = plan.stroke_surface_m.back(), n = plan.stroke_normal.back();
    const SurfaceDistance d = distance_to_isosurface(f, iso.tau, s + tangent * ds, opt);
    if (!d.found || core::norm(d.closest_m - s) < 0.1 * ds) break;  // the surface ends (or leaves the box)
    const Vec3 n_next = outward_normal(f, iso, d.closest_m, n);
    if (core::dot(n_next, n) < 0) break;  // the nearest point is another sheet's (a wall thinner than the step)
    tangent = core::normalized_or(tangent - n_next * core::dot(tangent, n_next), tangent);
    plan.stroke_length_m += core::norm(d.closest_m - s);
    plan.stroke_surface_m.push_back(d.closest_m);
    plan.stroke_normal.push_back(n_next);
  }
}

/// The press depth: what the force allows, at most thickness_fraction of the thinnest wall
/// under the stroke (one depth: the hand's target moves with the surface, not toward it).
void choose_depths(const core::SampleField& f, const core::Isosurface& iso, const TouchPlanOptions& o, TouchPlan& plan) {
  const double reach = plan.force_depth_m / o.thickness_fraction;
  plan.stroke_depth_m.clear();
  plan.min_thickness_m = std::numeric_limits<double>::infinity();
  const std::size_t n = plan.stroke_surface_m.size();
  const std::size_t every = std::max<std::size_t>(1, (n + kMaxWallChecks - 1) / kMaxWallChecks);
  const auto check = [&](std::size_t i) {
    const double wall = thickness_under(f, iso, plan.stroke_surface_m[i], plan.stroke_normal[i], reach);
    plan.min_thickness_m = std::min(plan.min_thickness_m, wall);
  };
  for (std::size_t i = 0; i < n; i += every) check(i);
  if (n > 0 && (n - 1) % every != 0) check(n - 1);  // the stroke's end too
  plan.press_depth_m = plan.min_press_depth_m = std::min(plan.force_depth_m, o.thickness_fraction * plan.min_thickness_m);
  plan.stroke_depth_m.assign(plan.stroke_surface_m.size(), plan.press_depth_m);
}

/// How well a stroke holds the surface: its shallowest press times the share of the asked
/// length it walked.
double score(const TouchPlan& plan, double length) {
  return plan.min_press_depth_m * (length > 0 ? std::min(1.0, plan.stroke_length_m / length) : 1.0);
}

/// The waypoints: rest above the contact, approach and press along its normal, hold, the
/// stroke d under each surface point along its normal, lift along the last normal, rest.
void add_waypoints(const sim::ScriptParams& p, TouchPlan& plan) {
  sim::TouchScript& s = plan.script;
  const double d = plan.press_depth_m;
  const Vec3 p0 = plan.stroke_surface_m.front(), n0 = plan.stroke_normal.front();
  double t = 0;
  Vec3 prev = p0 + n0 * p.approach_distance_m;
  auto add = [&](const Vec3& pos, double dt) {
    t += dt;
    s.waypoints.push_back({t, pos});
    prev = pos;
  };
  add(prev, 0.0);
  add(prev, p.rest_s);
  add(p0, p.approach_distance_m / p.approach_speed_m_s);
  s.t_press = t;
  add(p0 - n0 * d, d / p.press_speed_m_s);
  add(prev, p.hold_s);
  s.t_stroke = t;
  for (std::size_t i = 1; i < plan.stroke_surface_m.size(); ++i) {
    const Vec3 tgt = plan.stroke_surface_m[i] - plan.stroke_normal[i] * plan.stroke_depth_m[i];
    add(tgt, core::norm(tgt - prev) / p.stroke_speed_m_s);
  }
  s.t_lift = t;
  const Vec3 up = plan.stroke_surface_m.back() + plan.stroke_normal.back() * p.approach_distance_m;
  add(up, core::norm(up - prev) / p.approach_speed_m_s);
  add(up, p.rest_s);
  s.duration_s = t;
}

/// What every candidate plan shares.
struct Ctx {
  const core::SampleField& f;
  core::Isosurface iso;
  const TouchPlanOptions& o;
  const sim::ScriptParams& p;
  double force_depth;
};

/// A plan from surface point `s` (outward normal `n`) walking `length` along `t`, its depths chosen.
TouchPlan walked(const Ctx& c, const Vec3& s, const Vec3& n, const Vec3& t, double length, double direction_deg) {
  TouchPlan plan;
  plan.script.contact_point_m = s;
  plan.script.contact_normal = n;
  plan.script.lift_retrace = c.p.lift_retrace;
  plan.stroke_surface_m = {s};
  plan.stroke_normal = {n};
  plan.force_depth_m = c.force_depth;
  plan.direction_deg = direction_deg;
  walk_stroke(c.f, c.iso, t, length, plan);
  choose_depths(c.f, c.iso, c.o, plan);
  return plan;
}

/// From `s`: along `t` (the scene's direction), unless the wall thins or the surface ends
/// along it; then the best of kDirections directions around `n` (the first kept on a tie).
TouchPlan best_direction(const Ctx& c, const Vec3& s, const Vec3& n, const Vec3& t) {
  TouchPlan plan;
  for (int k = 0; k < kDirections; ++k) {
    const double a = 2.0 * std::numbers::pi * k / kDirections;
    TouchPlan cand = walked(c, s, n, t * std::cos(a) + core::cross(n, t) * std::sin(a), c.p.stroke_length_m,
                            360.0 * k / kDirections);
    if (k == 0 || score(cand, c.p.stroke_length_m) > score(plan, c.p.stroke_length_m)) plan = std::move(cand);
    plan.directions_tried = k + 1;
    if (k == 0 && score(plan, c.p.stroke_length_m) >= kGoodEnough * c.force_depth) break;
  }
  return plan;
}

/// True where the hand's approach to `s` (approach_distance_m along `n`) stays outside the
/// object, sampled every quarter voxel.
bool approach_clear(const Ctx& c, const Vec3& s, const Vec3& n) {
  const double h = std::max(0.25 * smallest_spacing(c.f.grid), c.p.approach_distance_m / kMaxMarch);
  for (double t = 2 * h; t <= c.p.approach_distance_m; t += h)
    if (c.iso.contains(servo::sample_value(c.f, s + n * t))) return false;
  return true;
}

/// The tangent nearest `t0` at a point of outward normal `n`.
Vec3 tangent_near(const Vec3& t0, const Vec3& n) {
  return core::normalized_or(t0 - n * core::dot(t0, n), core::normalized_or(core::cross(n, {0, 0, 1}), {1, 0, 0}));
}

/// The best start near the ray's contact (walks of kStartReach from it in kDirections
/// directions, a start every kStartEvery steps), or `plan` if none scores higher.
TouchPlan best_near_start(const Ctx& c, const sim::TouchScript& cast, const Vec3& t0, TouchPlan plan) {
  const Vec3 n0 = cast.contact_normal;
  for (int k = 0; k < kDirections; ++k) {
    const double a = 2.0 * std::numbers::pi * k / kDirections;
    const TouchPlan probe = walked(c, cast.contact_point_m, n0, t0 * std::cos(a) + core::cross(n0, t0) * std::sin(a),
                                   kStartReach, 0.0);
    const std::size_t every = std::max(kStartEvery, probe.stroke_surface_m.size() / kMaxStarts);
    for (std::size_t j = every; j < probe.stroke_surface_m.size(); j += every) {
      const Vec3 s = probe.stroke_surface_m[j], n = probe.stroke_normal[j];
      if (!approach_clear(c, s, n)) continue;
      TouchPlan cand = best_direction(c, s, n, tangent_near(t0, n));
      if (score(cand, c.p.stroke_length_m) > score(plan, c.p.stroke_length_m)) plan = std::move(cand);
    }
  }
  return plan;
}

/// The best start among the first contacts of rays parallel to the scene's ray from a grid
/// over the middle of the box (across the two axes the ray runs least along), or `plan` if
/// none scores higher. A ray that meets no surface is skipped.
TouchPlan best_far_start(const Ctx& c, const servo::HriParams& hri, const Vec3& t0, TouchPlan plan) {
  const Vec3 d = c.p.ray_direction;
  const int along = std::abs(d.x) >= std::max(std::abs(d.y), std::abs(d.z)) ? 0 : std::abs(d.y) >= std::abs(d.z) ? 1 : 2;
  const int u = (along + 1) % 3, v = (along + 2) % 3;
  for (int i = 0; i < kFarGrid; ++i)
    for (int j = 0; j < kFarGrid; ++j) {
      sim::ScriptParams ray = c.p;
      ray.stroke_length_m = 0;
      double* frac[3] = {&ray.ray_origin_frac.x, &ray.ray_origin_frac.y, &ray.ray_origin_frac.z};
      *frac[u] = kFarLo + (kFarHi - kFarLo) * i / (kFarGrid - 1);
      *frac[v] = kFarLo + (kFarHi - kFarLo) * j / (kFarGrid - 1);
      sim::TouchScript cast;
      try {
        cast = sim::make_touch_script(c.f, hri, ray);
      } catch (const std::runtime_error&) {
        continue;  // this ray meets no surface
      }
      const Vec3 s = cast.contact_point_m, n = cast.contact_normal;
      if (!approach_clear(c, s, n)) continue;
      TouchPlan cand = best_direction(c, s, n, tangent_near(t0, n));
      if (score(cand, c.p.stroke_length_m) > score(plan, c.p.stroke_length_m)) plan = std::move(cand);
    }
  return plan;
}

}  // namespace

double force_press_depth_m(const servo::HriParams& hri, const sim::SimDeviceParams& device, double force_fraction) {
  return hri.world_per_device * force_fraction * hri.force_limit_n *
         (1.0 / hri.stiffness_n_per_m + 1.0 / device.hand_stiffness_n_per_m);
}

TouchPlan plan_touch(const core::SampleField& truth, const servo::HriParams& hri, const sim::SimDeviceParams& device,
                     const sim::ScriptParams& p, const TouchPlanOptions& o) {
  // The contact: where the ray script finds it (its checks and messages); the rest is planned here.
  sim::ScriptParams ray = p;
  ray.stroke_length_m = 0;
  const sim::TouchScript cast = sim::make_touch_script(truth, hri, ray);
  const Ctx c{truth, core::Isosurface{hri.tau, hri.inside}, o, p, force_press_depth_m(hri, device, o.force_fraction)};
  const Vec3 n0 = cast.contact_normal;
  const Vec3 t0 = tangent_near(p.stroke_direction, n0);
  TouchPlan plan = best_direction(c, cast.contact_point_m, n0, t0);
  // A thin wall at the ray's contact: the best start near it on the surface, by the same
  // score; still none good: the best of other rays' contacts (a larger, thicker patch).
  const double good = kGoodEnough * c.force_depth;
  if (score(plan, p.stroke_length_m) < good) plan = best_near_start(c, cast, t0, std::move(plan));
  if (score(plan, p.stroke_length_m) < good) plan = best_far_start(c, hri, t0, std::move(plan));
  add_waypoints(p, plan);
  return plan;
}

}  // namespace isotouch::eval
