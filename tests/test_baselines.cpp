// The two baselines of the paper's Table 1 on analytic fields.
#include <gtest/gtest.h>

#include <cmath>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/servo/baselines.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

namespace {
const Vec3 kUp{0, 0, 1};
const Vec3 kP{0.016, 0.016, 0.010};
BaselineParams params() {
  BaselineParams p;
  p.tau = 0;
  p.stiffness_n_per_m = 500;
  p.damping_n_s_per_m = 0;
  p.force_limit_n = 10;
  return p;
}
}  // namespace

TEST(Avila, StiffnessForceFromTheDensityBasedPenetration) {
  const SampleField f = plane_field(kUp, kP);
  AvilaRenderer r(params());
  EXPECT_FALSE(r.tick(f, {0.016, 0.016, 0.011}).contact);
  const HriTick t = r.tick(f, {0.016, 0.016, 0.009});
  ASSERT_TRUE(t.contact);
  EXPECT_NEAR(t.force_n.z, 500 * 0.001, 1e-6);  // linear field: the estimate is exact
  EXPECT_NEAR(t.force_n.x, 0, 1e-9);
  EXPECT_NEAR(t.vhip_m.z, 0.010, 1e-8);
}

TEST(Avila, HasNoMemoryStartingInsidePushes) {
  const SampleField f = plane_field(kUp, kP);
  AvilaRenderer r(params());
  const HriTick t = r.tick(f, {0.016, 0.016, 0.007});  // first tick, 3 mm deep
  EXPECT_TRUE(t.contact);
  EXPECT_NEAR(t.force_n.z, 1.5, 1e-5);
}

TEST(Avila, RetardingForceOpposesMotionInside) {
  const SampleField f = plane_field(kUp, kP);
  BaselineParams p = params();
  p.damping_n_s_per_m = 2;
  AvilaRenderer r(p);
  r.tick(f, {0.016, 0.016, 0.009});
  const HriTick t = r.tick(f, {0.0165, 0.016, 0.009});  // 0.5 m/s along +x inside
  EXPECT_NEAR(t.force_n.x, -1.0, 1e-6);
}

TEST(Blezek, ContactPointOnTheSurfaceAndForceAlongTheNormal) {
  const Vec3 c{0.024, 0.024, 0.024};
  const SampleField f = sphere_field(c, 0.015);
  BlezekRenderer r(params());
  r.tick(f, c + Vec3{0, 0, 0.016});
  long contact = 0;
  double max_surface = 0, max_angle = 0, max_spring_error = 0;
  for (int k = 0; k < 3000; ++k) {
    const Vec3 hip = c + Vec3{std::sin(0.5 * k / 3000.0), 0, std::cos(0.5 * k / 3000.0)} * 0.0145;
    const HriTick t = r.tick(f, hip);  // slide 7.5 mm over the sphere, 0.5 mm deep
    if (!t.contact) continue;
    ++contact;
    max_surface = std::max(max_surface, std::abs(norm(t.vhip_m - c) - 0.015));
    const Vec3 n_true = (t.vhip_m - c) / norm(t.vhip_m - c);
    const double m = norm(t.force_n);
    // A zero force has no direction: it counts as 180 deg (and as a spring error of K |d|).
    max_angle = std::max(max_angle, m > 0 ? std::acos(std::clamp(dot(t.force_n / m, n_true), -1.0, 1.0)) * 180 / M_PI : 180.0);
    // No damping: |F| = K |HIP - VHIP| (eq. 3 of the contact point the inching found).
    max_spring_error = std::max(max_spring_error, std::abs(m - 500.0 * norm(hip - t.vhip_m)));
  }
  std::printf("Blezek-Robb on the sphere: max surface error %.4f mm, max angle %.3f deg, max | |F| - K |d| | %.2e N\n",
              max_surface * 1e3, max_angle, max_spring_error);
  EXPECT_LT(max_spring_error, 1e-9);
  EXPECT_EQ(contact, 3000);
  EXPECT_LT(max_surface, 5e-5);   // 0.05 voxel
  EXPECT_LT(max_angle, 1.0);      // HIP - VHIP parallel to the normal: inching converged
}

TEST(Blezek, LeavingEndsContact) {
  const SampleField f = plane_field(kUp, kP);
  BlezekRenderer r(params());
  r.tick(f, {0.016, 0.016, 0.011});
  EXPECT_TRUE(r.tick(f, {0.016, 0.016, 0.009}).contact);
  const HriTick out = r.tick(f, {0.016, 0.016, 0.0105});
  EXPECT_FALSE(out.contact);
  EXPECT_EQ(norm(out.force_n), 0.0);
}

TEST(Blezek, StartingInsideGivesNoForce) {
  const SampleField f = plane_field(kUp, kP);
  BlezekRenderer r(params());
  for (double z = 0.007; z < 0.0095; z += 0.0005) EXPECT_EQ(norm(r.tick(f, {0.016, 0.016, z}).force_n), 0.0);
}

TEST(Blezek, VanishingGradientFailsTransparent) {
  SampleField f = plane_field(kUp, kP);
  BlezekRenderer r(params());
  r.tick(f, {0.016, 0.016, 0.011});
  ASSERT_TRUE(r.tick(f, {0.016, 0.016, 0.009}).contact);
  for (auto& s : f.samples) s.value = 1.f;  // the volume edited to a constant: no gradient anywhere
  const HriTick t = r.tick(f, {0.016, 0.016, 0.009});
  EXPECT_TRUE(t.contact);               // still in contact ...
  EXPECT_EQ(norm(t.force_n), 0.0);      // ... but inching failed: haptically transparent, never NaN
}

TEST(Baselines, NonFiniteHipIsAFault) {
  const SampleField f = plane_field(kUp, kP);
  AvilaRenderer a(params());
  BlezekRenderer b(params());
  for (Renderer* r : std::initializer_list<Renderer*>{&a, &b}) {
    const HriTick t = r->tick(f, {std::nan(""), 0, 0});
    EXPECT_TRUE(t.fault) << r->name();
    EXPECT_EQ(norm(t.force_n), 0.0);
  }
}
