// Simulated device, touch script and the headless loop.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <vector>

#include "isotouch/sim/headless.h"
#include "isotouch/servo/sampling.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

namespace {
// Sphere of radius R [m] around c as a distance field in mm (positive inside), exact samples.
SampleField sphere_field(double R) {
  SampleField f;
  f.grid.dims = {48, 48, 48};
  f.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  f.samples.resize(f.grid.voxel_count());
  const Vec3 c = f.grid.centre_m();
  for (int z = 0; z < 48; ++z)
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x) {
        const Vec3 p = f.grid.to_world({double(x), double(y), double(z)});
        const Vec3 u = normalized_or(p - c, {0, 0, 1});
        f.samples[f.grid.index(x, y, z)] = {float((R - norm(p - c)) * 1000), float(-u.x * 1000),
                                            float(-u.y * 1000), float(-u.z * 1000)};
      }
  return f;
}

/// HRI at isovalue 0 (sphere_field's surface) and a script from above the sphere.
HriParams iso0() {
  HriParams h;
  h.tau = 0;
  return h;
}
ScriptParams from_above(double stroke_m) {
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, 1.3};
  sp.stroke_length_m = stroke_m;
  return sp;
}

/// The headless loop on `field` from the script's start: returns the trace; `saturated`, if
/// given, gets the device's count of clipped commands.
std::vector<TraceRow> headless_run(const std::shared_ptr<const SampleField>& field, const HriParams& h,
                                   const ScriptParams& sp, const SimDeviceParams& dp = {}, long* saturated = nullptr) {
  TripleBuffer<SampleField> tb;
  tb.publish(field);
  const TouchScript s = make_touch_script(*field, h, sp);
  WorkspaceTransform xf;
  xf.translation_m = field->grid.centre_m();
  Vec3 p0, v0;
  s.at(0, p0, v0);
  SimDevice d(dp, xf.to_device(p0));
  HriRenderer r(h);
  std::vector<TraceRow> trace = run_headless(tb, r, d, xf, s, 1000.0);
  if (saturated) *saturated = d.saturated_commands();
  return trace;
}
}  // namespace

TEST(SimDevice, HandSpringBringsTheMassToTheTarget) {
  SimDevice d({}, {0, 0, 0});
  for (int k = 0; k < 3000; ++k) d.step(1e-3, {0.01, -0.02, 0.005}, {});
  EXPECT_NEAR(d.position().x, 0.01, 1e-6);
  EXPECT_NEAR(d.position().y, -0.02, 1e-6);
  EXPECT_NEAR(norm(d.velocity()), 0.0, 1e-5);
}

TEST(SimDevice, RenderedForceActsBackOnTheMotion) {
  SimDeviceParams p;
  SimDevice d(p, {0, 0, 0});
  d.command_force({0, 0, 1.5});  // held (zero-order hold) across steps
  for (int k = 0; k < 3000; ++k) d.step(1e-3, {0, 0, 0}, {});
  // Equilibrium: hand spring balances the force, offset = F / K_hand.
  EXPECT_NEAR(d.position().z, 1.5 / p.hand_stiffness_n_per_m, 1e-6);
}

TEST(Script, PhasesAndContactPointOnTheSphere) {
  const double R = 0.015;
  const SampleField f = sphere_field(R);
  HriParams h;
  h.tau = 0;
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, 1.3};
  sp.ray_direction = {0, 0, -1};
  sp.stroke_length_m = 0.010;  // stays on the cap of the sphere
  const TouchScript s = make_touch_script(f, h, sp);
  const Vec3 c = f.grid.centre_m();
  EXPECT_NEAR(norm(s.contact_point_m - c), R, 5e-5);  // 0.05 voxel: trilinear field
  EXPECT_NEAR(s.contact_normal.z, 1.0, 1e-3);
  EXPECT_LT(0.0, s.t_press);
  EXPECT_LT(s.t_press, s.t_stroke);
  EXPECT_LT(s.t_stroke, s.t_lift);
  EXPECT_LT(s.t_lift, s.duration_s);
  Vec3 p, v;
  s.at(0, p, v);
  EXPECT_NEAR(norm(p - c) - R, sp.approach_distance_m, 5e-5);
  // Mid-stroke the hand target is press_depth below the surface under it, measured along
  // the first contact normal (the hand keeps pressing "down"): radially a little less.
  s.at(0.5 * (s.t_stroke + s.t_lift), p, v);
  const double dx = p.x - c.x, dy = p.y - c.y;
  const double surface_z = c.z + std::sqrt(R * R - dx * dx - dy * dy);
  EXPECT_NEAR(surface_z - p.z, sp.press_depth_m, 2e-4);
  EXPECT_NEAR(norm(v), sp.stroke_speed_m_s, 0.3 * sp.stroke_speed_m_s);
}

// The lift retraced along a tool path that wanders off the straight line: the hand's target
// goes from where the lift began through the path's points, last first, to the straight
// lift's end, at one steady speed over the straight lift's time; nothing else changes.
TEST(Script, RetraceLiftGoesBackAlongTheToolsPath) {
  const SampleField f = sphere_field(0.015);
  const TouchScript s = make_touch_script(f, iso0(), from_above(0.0));
  const Vec3 c = s.contact_point_m, n = s.contact_normal;
  const std::vector<Vec3> path = {c + n * 4e-3, c + Vec3{2e-3, 0, 0}, c + Vec3{1e-3, 3e-3, 0} - n * 5e-3};
  TouchScript r = s;
  r.retrace_lift({});
  ASSERT_EQ(r.waypoints.size(), s.waypoints.size());  // an empty path changes nothing
  r.retrace_lift(path);
  EXPECT_EQ(r.duration_s, s.duration_s);
  ASSERT_EQ(r.waypoints.size(), s.waypoints.size() + path.size());
  Vec3 p, v, q, w;
  for (double t = 0; t <= s.t_lift; t += 0.01) {  // the press and hold as they were
    s.at(t, p, v);
    r.at(t, q, w);
    EXPECT_EQ(norm(p - q), 0.0) << t;
  }
  s.at(s.duration_s, p, v);
  r.at(r.duration_s, q, w);
  EXPECT_EQ(norm(p - q), 0.0);  // the same end
  // Find the lift's waypoints: the one at t_lift, the path backwards, the straight lift's end.
  std::size_t i = 0;
  while (r.waypoints[i + 1].t_s <= r.t_lift) ++i;
  const double speed = norm(r.waypoints[i + 1].pos_m - r.waypoints[i].pos_m) /
                       (r.waypoints[i + 1].t_s - r.waypoints[i].t_s);
  for (std::size_t k = 0; k < path.size(); ++k) {
    EXPECT_EQ(norm(r.waypoints[i + 1 + k].pos_m - path[path.size() - 1 - k]), 0.0) << k;
    const auto& a = r.waypoints[i + k];
    const auto& b = r.waypoints[i + 1 + k];
    EXPECT_NEAR(norm(b.pos_m - a.pos_m) / (b.t_s - a.t_s), speed, 1e-9 * speed) << k;
  }
  const auto& end = r.waypoints[i + 1 + path.size()];
  const auto& straight_end = s.waypoints[i + 1];  // the waypoints up to i are s's
  EXPECT_EQ(norm(end.pos_m - straight_end.pos_m), 0.0);
  EXPECT_NEAR(end.t_s, straight_end.t_s, 1e-12);
}

TEST(Script, RayThatMissesIsAClearError) {
  const SampleField f = sphere_field(0.015);
  HriParams h;
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, 1.3};
  sp.ray_direction = {0, 0, 1};  // away from the sphere
  EXPECT_THROW(make_touch_script(f, h, sp), std::runtime_error);
  sp.ray_origin_frac = {0.5, 0.5, 0.5};  // starts inside
  EXPECT_THROW(make_touch_script(f, h, sp), std::runtime_error);
}

TEST(Headless, DeterministicAndTouches) {
  const auto field = std::make_shared<const SampleField>(sphere_field(0.015));
  HriParams h;
  h.tau = 0;
  h.plane_update_period = 5;
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, 1.3};
  sp.stroke_length_m = 0.015;
  const auto a = headless_run(field, h, sp), b = headless_run(field, h, sp);
  ASSERT_EQ(a.size(), b.size());
  long contact = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].hip_m.z, b[i].hip_m.z);
    ASSERT_EQ(a[i].force_n.z, b[i].force_n.z);
    contact += a[i].contact;
    EXPECT_LE(norm(a[i].force_n), h.force_limit_n + 1e-12);
  }
  EXPECT_GT(contact, 500);
}

// The trace's force is the one the device took (after its own clip at force_max_n), not the
// renderer's: a device that takes at most 0.5 N under a renderer allowed 3.3 N.
TEST(Headless, TheTraceHoldsTheForceTheDeviceTook) {
  const auto field = std::make_shared<const SampleField>(sphere_field(0.015));
  const HriParams h = iso0();
  const ScriptParams sp = from_above(ScriptParams{}.stroke_length_m);
  SimDeviceParams dp;
  dp.force_max_n = 0.5;
  long clipped = 0;
  const auto trace = headless_run(field, h, sp, dp, &clipped);
  double worst = 0;
  for (const auto& row : trace) worst = std::max(worst, norm(row.force_n));
  EXPECT_GT(clipped, 10);  // the renderer asked for more
  EXPECT_LE(worst, 0.5 + 1e-12);
  EXPECT_GT(worst, 0.5 - 1e-9);
}

TEST(SimDevice, SaturatesAndRefusesNonFiniteCommands) {
  SimDeviceParams p;
  p.force_max_n = 2.0;
  SimDevice d(p, {0, 0, 0});
  d.command_force({0, 3, 4});
  EXPECT_NEAR(norm(d.applied_force()), 2.0, 1e-12);
  EXPECT_NEAR(d.applied_force().y / d.applied_force().z, 0.75, 1e-12);
  d.command_force({std::nan(""), 0, 0});
  EXPECT_EQ(norm(d.applied_force()), 0.0);
  EXPECT_EQ(d.refused_commands(), 1);
  EXPECT_EQ(d.saturated_commands(), 1);
}

TEST(SimDevice, EncoderQuantizesTheReading) {
  SimDeviceParams p;
  p.encoder_resolution_m = 1e-4;
  SimDevice d(p, {0.00123, -0.00017, 0.0});
  EXPECT_NEAR(d.position().x, 0.0012, 1e-12);
  EXPECT_NEAR(d.position().y, -0.0002, 1e-12);
  EXPECT_NEAR(d.true_position().x, 0.00123, 1e-15);
}

TEST(SimDevice, CoulombFrictionHoldsBelowAndSlidesAbove) {
  SimDeviceParams p;
  p.coulomb_friction_n = 0.5;
  p.hand_stiffness_n_per_m = 100;
  p.hand_damping_n_s_per_m = 0;
  SimDevice held(p, {0, 0, 0});
  for (int k = 0; k < 500; ++k) held.step(1e-3, {0.004, 0, 0}, {});  // 0.4 N < 0.5 N
  EXPECT_EQ(held.true_position().x, 0.0);
  SimDevice slides(p, {0, 0, 0});
  for (int k = 0; k < 3000; ++k) slides.step(1e-3, {0.02, 0, 0}, {});  // 2 N > 0.5 N
  // Comes to rest where the spring force has fallen to the friction level (or closer).
  EXPECT_GT(slides.true_position().x, 0.02 - 0.5 / 100 - 1e-6);
  EXPECT_LT(slides.true_position().x, 0.02 + 0.5 / 100 + 1e-6);
}

TEST(SimDevice, EnergyBookkeepingOfAConstantForce) {
  SimDeviceParams p;
  p.hand_stiffness_n_per_m = 0;
  p.hand_damping_n_s_per_m = 0;
  p.damping_n_s_per_m = 0;
  SimDevice d(p, {0, 0, 0});
  d.command_force({1.0, 0, 0});
  for (int k = 0; k < 100; ++k) d.step(1e-3, {}, {});
  // Work = F x = kinetic energy for a free mass.
  EXPECT_NEAR(d.rendered_work_j(), 1.0 * d.true_position().x, 1e-12);
  EXPECT_NEAR(d.rendered_work_j(), 0.5 * p.mass_kg * d.velocity().x * d.velocity().x, 1e-3 * d.rendered_work_j());  // Euler: (N+1)/N
}

// ---- a device too light for its substeps diverged to NaN --------------------------
TEST(SimDevice, MinStableSubstepsMatchesTheJuryBound) {
  SimDeviceParams p;
  p.mass_kg = 1e-4;  // hand 300 N/m, 5 + 0.01 N s/m
  const double dt = 1e-3;
  const int n = min_stable_substeps(p, dt);
  // Independent check of the bound: h = dt / n satisfies a + 2b <= 2, h' = dt / (n - 1) not.
  auto ab = [&](int steps) {
    const double h = dt / steps;
    return h * h * p.hand_stiffness_n_per_m / p.mass_kg + 2 * h * (p.hand_damping_n_s_per_m + p.damping_n_s_per_m) / p.mass_kg;
  };
  EXPECT_LE(ab(n), 2.0);
  EXPECT_GT(ab(n - 1), 2.0);
  EXPECT_EQ(n, 51);
  EXPECT_EQ(min_stable_substeps(SimDeviceParams{}, dt), 1);  // the default device: 20 are plenty
  EXPECT_NEAR(min_stable_mass_kg(p, dt, n), 0.5 * (300 * 1e-3 / n * 1e-3 / n + 2 * 5.01 * 1e-3 / n), 1e-15);
}

TEST(SimDevice, LightDeviceStaysFinite) {
  // With the old fixed 20 substeps, h c / m = 2.5 > 2: the velocity flips sign and grows
  // every substep. Now the device raises its substeps and settles on the target.
  SimDeviceParams p;
  p.mass_kg = 1e-4;
  SimDevice d(p, {0, 0, 0});
  for (int k = 0; k < 2000; ++k) d.step(1e-3, {0.01, 0, 0}, {});
  EXPECT_EQ(d.substeps_used(), 51);
  ASSERT_TRUE(finite(d.position()));
  EXPECT_NEAR(d.position().x, 0.01, 1e-6);
}

TEST(Headless, LightDeviceHasNoFaults) {
  // The run: mass 1e-4 kg, 3311 of 3411 ticks were faults. Same loop on a sphere.
  const auto field = std::make_shared<const SampleField>(sphere_field(0.015));
  const HriParams h = iso0();
  const ScriptParams sp = from_above(0.010);
  SimDeviceParams dp;
  dp.mass_kg = 1e-4;
  const auto trace = headless_run(field, h, sp, dp);
  long faults = 0, contact = 0;
  for (const auto& row : trace) {
    faults += row.fault;
    contact += row.contact;
    ASSERT_TRUE(finite(row.force_n));
  }
  EXPECT_EQ(faults, 0);
  EXPECT_GT(contact, 300);
}

// ---- the script's march is bounded whatever the grid or the ray --------------------
// Wall-clock bound for the bounded marches below: the bounded march takes 0.1-0.7 s in a
// release build and a few seconds under ThreadSanitizer; the unbounded one takes minutes
// (release) to hours (TSan), so 30 s separates them on any build.
constexpr double kBoundedMarchS = 30.0;

TEST(Script, MarchIsBoundedOnAbsurdGrids) {
  // A grid 4700 km wide along x and 1 mm along y, z: a march in quarter-millimetre steps
  // takes 2e10 samples (minutes). (Volume files are limited to 10 m; scripts are not.)
  SampleField f = sphere_field(0.015);
  f.grid.spacing_m = {1e5, 1e-3, 1e-3};
  HriParams h;
  h.tau = 1e9;  // no isosurface: the march runs to the end
  ScriptParams sp;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_THROW(make_touch_script(f, h, sp), std::runtime_error);
  // Along the huge axis: the step budget bounds it.
  sp.ray_origin_frac = {-1, 0.5, 0.5};
  sp.ray_direction = {1, 0, 0};
  EXPECT_THROW(make_touch_script(f, h, sp), std::runtime_error);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(s, kBoundedMarchS);
}

TEST(Script, RayOriginFarAwayIsRejectedOrFast) {
  const SampleField f = sphere_field(0.015);
  HriParams h;
  h.tau = 0;
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, -1e6};
  try {
    make_touch_script(f, h, sp);
    FAIL() << "accepted ray_origin_frac z = -1e6";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("ray_origin_frac"), std::string::npos) << e.what();
  }
  // Within the accepted range, a far start marches only inside the box: still fast.
  sp.ray_origin_frac = {0.5, 0.5, 3.0};
  const auto t0 = std::chrono::steady_clock::now();
  const TouchScript s = make_touch_script(f, h, sp);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), kBoundedMarchS);
  EXPECT_NEAR(norm(s.contact_point_m - f.grid.centre_m()), 0.015, 5e-5);
}

TEST(Script, MessagesAreInMillimetres) {
  const SampleField f = sphere_field(0.015);
  HriParams h;
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, 1.3};
  sp.ray_direction = {0, 0, 1};
  try {
    make_touch_script(f, h, sp);
    FAIL();
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("(23.5, 23.5, 61.1) mm"), std::string::npos) << m;  // 47 mm * (0.5, 0.5, 1.3)
    EXPECT_EQ(m.find(") m "), std::string::npos) << m;
  }
}

TEST(Script, StrokeIsBoundedOnAbsurdGrids) {
  // 1 nm along x, 1 mm along y, z: every stroke point marches 38 mm along -z in steps of a
  // quarter of the smallest spacing: 1.5e8 samples per point, 10000 points (ds = 1 um).
  SampleField f;
  f.grid.dims = {8, 48, 48};
  f.grid.spacing_m = {1e-9, 1e-3, 1e-3};
  f.samples.assign(f.grid.voxel_count(), Sample{0, 0, 0, 0});
  for (int z = 0; z < 48; ++z)
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 8; ++x) f.samples[f.grid.index(x, y, z)] = {float(24 - z), 0, 0, -1e3f};
  HriParams h;
  h.tau = 0.5;  // a plane between z = 23 and 24 mm
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.3, 0.9};
  sp.ray_direction = {0, 0, -1};
  sp.stroke_direction = {0, 1, 0};
  sp.stroke_length_m = 0.01;
  const auto t0 = std::chrono::steady_clock::now();
  const TouchScript s = make_touch_script(f, h, sp);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), kBoundedMarchS);
  EXPECT_NEAR(s.contact_point_m.z, 23.5e-3, 1e-6);
  Vec3 p, v;
  s.at(0.5 * (s.t_stroke + s.t_lift), p, v);
  EXPECT_NEAR(p.z, 23.5e-3 - sp.press_depth_m, 1e-5);  // the stroke found the plane
}
