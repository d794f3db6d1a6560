// Stability against Colgate-Schenkel, time-domain passivity, extreme cases, random ticks.
#include <gtest/gtest.h>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/stability.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

namespace {
const Vec3 kP{0.016, 0.016, 0.010};
const Vec3 kUp{0, 0, 1};
SampleField wall() { return plane_field(kUp, kP); }
}  // namespace

TEST(Stability, HalfTheBoundIsPassive) {
  const SampleField f = wall();
  for (double T : {1e-3, 2.5e-4, 1e-4}) {
    HeldContact h;
    h.period_s = T;
    h.stiffness_n_per_m = 0.5 * colgate_k_max(h.device.damping_n_s_per_m, 0, T);
    const HeldContactResult r = simulate_held_contact(f, kP, kUp, h);
    EXPECT_GT(r.contact_ticks, r.ticks / 2);
    // The energy the display (wall + device damping) handed the user is not positive.
    EXPECT_LE(r.energy_out_j, 0.0) << "T = " << T;
    EXPECT_FALSE(r.sustained_oscillation) << "T = " << T;
  }
}

TEST(Stability, TwiceTheBoundOscillates) {
  const SampleField f = wall();
  for (double T : {1e-3, 2.5e-4, 1e-4}) {
    HeldContact h;
    h.period_s = T;
    h.stiffness_n_per_m = 2.0 * colgate_k_max(h.device.damping_n_s_per_m, 0, T);
    const HeldContactResult r = simulate_held_contact(f, kP, kUp, h);
    EXPECT_TRUE(r.sustained_oscillation) << "T = " << T << " early " << r.early_energy_j << " late " << r.late_energy_j;
    EXPECT_TRUE(r.gains_energy) << "T = " << T;
  }
}

TEST(Stability, PassivityControllerStabilisesTwiceTheBound) {
  const SampleField f = wall();
  HeldContact h;
  h.stiffness_n_per_m = 2.0 * colgate_k_max(h.device.damping_n_s_per_m, 0, h.period_s);
  h.passivity_controller = true;
  const HeldContactResult r = simulate_held_contact(f, kP, kUp, h);
  EXPECT_FALSE(r.sustained_oscillation) << "early " << r.early_energy_j << " late " << r.late_energy_j;
  EXPECT_FALSE(r.nonfinite);
  EXPECT_GT(r.contact_ticks, r.ticks / 2);
}

TEST(Stability, MeasuredKmaxIsNearTheColgateBound) {
  const SampleField f = wall();
  HeldContact h;
  const double bound = colgate_k_max(h.device.damping_n_s_per_m, 0, h.period_s);
  const double k = find_k_max(f, kP, kUp, h, bound / 10, bound * 10);
  std::printf("T = 1 ms, b = 1 N s/m: K_max measured %.0f N/m, bound %.0f N/m, ratio %.3f\n", k, bound, k / bound);
  EXPECT_GT(k / bound, 0.7);
  EXPECT_LT(k / bound, 1.3);
}

// One test per extreme case (the same cases are the rows of `isotouch stability`).
class Extreme : public ::testing::TestWithParam<int> {};
TEST_P(Extreme, Case) {
  const ExtremeCase c = run_extreme_case(GetParam());
  std::printf("%s: %s\n", c.name.c_str(), c.detail.c_str());
  EXPECT_TRUE(c.passed) << c.name << ": " << c.expectation << " -- " << c.detail;
}
INSTANTIATE_TEST_SUITE_P(All, Extreme, ::testing::Range(0, extreme_case_count()));

// Finite and bounded, and what can break beyond saturation: no force without contact, the
// force along the plane normal and pushing, the VHIP on the plane (see random_tick_property).
TEST(ExtremeCases, MillionRandomTicksKeepEveryProperty) {
  double ratio = 0;
  std::string detail;
  const long bad = random_tick_property(1000000, 12345, ratio, &detail);
  std::printf("random ticks: %s; max |F|/F_max %.6f\n", detail.c_str(), ratio);
  EXPECT_EQ(bad, 0) << detail;
  EXPECT_LE(ratio, 1.0 + 1e-12);
  EXPECT_GT(ratio, 0.99);  // the limit was reached: the test exercised saturation
}
