// The touch planned on the true isosurface (eval/touch_plan): on shapes whose surface is known
// in closed form, the hand's target stays the planned depth under the surface along the whole
// stroke. The depth is measured here from the shape's formula, not by the planner's search.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "isotouch/eval/touch_plan.h"
#include "isotouch/sim/analytic_fields.h"

namespace isotouch::eval {
namespace {
using core::Vec3;

servo::HriParams hri() {
  servo::HriParams h;
  h.tau = 0;  // the analytic fields are positive inside
  h.inside = core::InsideIs::kAbove;
  return h;  // K 800 N/m, force limit 3.3 N
}

/// The ray down the box's centre line from above, a stroke of `length` [m] along +x.
sim::ScriptParams script(double length) {
  sim::ScriptParams p;
  p.ray_origin_frac = {0.5, 0.5, 1.2};
  p.ray_direction = {0, 0, -1};
  p.stroke_direction = {1, 0, 0};
  p.stroke_length_m = length;
  return p;
}

/// The depth [m] the force fraction f allows with K and the hand spring in series, from the
/// parameters (f F_limit (1/K + 1/K_hand)).
double expected_force_depth(double f) {
  const servo::HriParams h = hri();
  const sim::SimDeviceParams dev;
  return f * h.force_limit_n * (1.0 / h.stiffness_n_per_m + 1.0 / dev.hand_stiffness_n_per_m);
}

/// Every stroke target (t_stroke < t <= t_lift, 1 ms apart): `depth` of it against the plan's
/// depth, within `tol` [m]; the largest miss.
double worst_depth_miss(const TouchPlan& plan, const std::function<double(const Vec3&)>& depth, double tol) {
  const sim::TouchScript& s = plan.script;
  // One depth along the whole stroke on these shapes (each point's wall is as thick).
  const auto [lo, hi] = std::minmax_element(plan.stroke_depth_m.begin(), plan.stroke_depth_m.end());
  EXPECT_LT(*hi - *lo, tol) << "planned depths from " << *lo * 1e3 << " to " << *hi * 1e3 << " mm";
  double worst = 0;
  for (double t = s.t_stroke + 1e-3; t <= s.t_lift; t += 1e-3) {
    Vec3 p, v;
    s.at(t, p, v);
    const double miss = std::abs(depth(p) - plan.press_depth_m);
    worst = std::max(worst, miss);
    if (miss > tol) ADD_FAILURE() << "t = " << t << " s: the target is " << depth(p) * 1e3 << " mm under the surface, planned "
                                  << plan.press_depth_m * 1e3 << " mm";
    if (miss > tol) break;
  }
  return worst;
}

TEST(TouchPlan, FollowsASphereOverItsShoulder) {
  // R 15 mm about the centre of a 48 mm box; a 20 mm stroke from the top walks 76 degrees
  // around it (a straight line would leave it at 15 mm).
  const Vec3 c{0.0235, 0.0235, 0.0235};
  const double r = 0.015;
  const core::SampleField f = sim::sphere_field(c, r, 48, 1e-3);
  const TouchPlan plan = plan_touch(f, hri(), {}, script(0.020));
  EXPECT_NEAR(plan.press_depth_m, expected_force_depth(0.6), 1e-12);
  EXPECT_NEAR(plan.stroke_length_m, 0.020, 1e-3);
  worst_depth_miss(plan, [&](const Vec3& p) { return r - core::norm(p - c); }, 0.1e-3);
  // The lift leaves along the normal where the stroke ended: its end is outside the sphere.
  Vec3 up, v;
  plan.script.at(plan.script.duration_s, up, v);
  EXPECT_GT(core::norm(up - c), r + 0.5 * script(0).approach_distance_m);
}

TEST(TouchPlan, KeepsItsDepthOnATiltedPlane) {
  const Vec3 n = core::normalized_or(Vec3{0.35, -0.25, 1.0}, {0, 0, 1});
  const Vec3 c{0.02, 0.02, 0.02};
  const core::SampleField f = sim::plane_field(n, c, 40, 1e-3);
  const TouchPlan plan = plan_touch(f, hri(), {}, script(0.015));
  EXPECT_NEAR(plan.press_depth_m, expected_force_depth(0.6), 1e-12);
  EXPECT_NEAR(plan.stroke_length_m, 0.015, 1e-3);
  worst_depth_miss(plan, [&](const Vec3& p) { return core::dot(n, c - p); }, 0.05e-3);
}

TEST(TouchPlan, PressesLessThanHalfAThinShellWall) {
  // A shell 5 mm thick about radius 28 mm: the force's depth (9 mm) would put the hand in the
  // hollow behind the wall; the plan presses at most 0.4 of the wall and follows its curve.
  const Vec3 c{0.04, 0.04, 0.04};
  const double r = 0.028, wall = 0.005;
  const core::SampleField f = sim::shell_field(c, r, wall, 80, 1e-3);
  const TouchPlan plan = plan_touch(f, hri(), {}, script(0.025));
  ASSERT_GT(expected_force_depth(0.6), wall);
  EXPECT_GT(plan.press_depth_m, 0.3 * wall);
  EXPECT_LE(plan.press_depth_m, 0.45 * wall);
  EXPECT_NEAR(plan.stroke_length_m, 0.025, 1e-3);
  worst_depth_miss(plan, [&](const Vec3& p) { return r + 0.5 * wall - core::norm(p - c); }, 0.1e-3);
}

TEST(TouchPlan, PressDepthScalesWithTheForceFraction) {
  const core::SampleField f = sim::plane_field({0, 0, 1}, {0.02, 0.02, 0.02}, 40, 1e-3);
  TouchPlanOptions o;
  o.force_fraction = 0.3;
  const TouchPlan plan = plan_touch(f, hri(), {}, script(0.01), o);
  EXPECT_NEAR(plan.press_depth_m, expected_force_depth(0.3), 1e-12);
  EXPECT_NEAR(force_press_depth_m(hri(), {}, 0.3), expected_force_depth(0.3), 1e-12);
}

}  // namespace
}  // namespace isotouch::eval
