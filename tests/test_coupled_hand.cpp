// The probe without a haptic device: the simulated device follows the hand target through
// the hand's spring and damper, and the rendered force pushes it back (a wall settles at the
// static balance of the two springs).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "isotouch/sim/coupled_hand_device.h"

using isotouch::core::Vec3;
using isotouch::sim::CoupledHandDevice;
using isotouch::sim::SimDeviceParams;

TEST(CoupledHand, FollowsTheHandInFreeSpace) {
  SimDeviceParams p;  // 0.08 kg, hand 300 N/m, 5 N s/m
  CoupledHandDevice d(p, {0, 0, 0}, 1e-3);
  d.set_hand_target({0.01, -0.02, 0.005});
  for (int k = 0; k < 2000; ++k) {
    (void)d.read_position_m();
    d.write_force_n({0, 0, 0});
  }
  const Vec3 x = d.read_position_m();
  EXPECT_NEAR(x.x, 0.01, 1e-4);
  EXPECT_NEAR(x.y, -0.02, 1e-4);
  EXPECT_NEAR(x.z, 0.005, 1e-4);
}

TEST(CoupledHand, AWallHoldsTheDeviceAtTheSpringsBalance) {
  SimDeviceParams p;
  CoupledHandDevice d(p, {-0.01, 0, 0}, 1e-3);
  const double K = 800, hand = 0.005;  // wall at x = 0 pushing back with K; the hand 5 mm inside
  d.set_hand_target({hand, 0, 0});
  for (int k = 0; k < 4000; ++k) {
    const Vec3 x = d.read_position_m();
    d.write_force_n({x.x > 0 ? -K * x.x : 0.0, 0, 0});
  }
  // 300 (hand - x) = K x
  const double expect = p.hand_stiffness_n_per_m * hand / (p.hand_stiffness_n_per_m + K);
  EXPECT_NEAR(d.read_position_m().x, expect, 0.03 * expect);
}

TEST(CoupledHand, NonFiniteTargetsAreIgnored) {
  CoupledHandDevice d(SimDeviceParams{}, {0, 0, 0}, 1e-3);
  d.set_hand_target({0.01, 0, 0});
  d.set_hand_target({std::numeric_limits<double>::quiet_NaN(), 0, 0});
  EXPECT_EQ(d.hand_target().x, 0.01);
  d.set_buttons(1u);
  EXPECT_EQ(d.buttons(), 1u);
}
