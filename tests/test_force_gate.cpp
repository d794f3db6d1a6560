// The force gate (servo/force_gate.h), step by step with given time steps (no clock): the
// peak is min(scene, device), a step demand rises at the rate limit (also after a zero tick),
// the RMS over the continuous window is held at the device's continuous limit (the time the
// peak may be held is the exponential window's closed form), non-finite demands are exact
// zeros, and the limits are derived from a device's capabilities.
#include <gtest/gtest.h>

#include <cmath>

#include "isotouch/servo/device_io.h"
#include "isotouch/servo/force_gate.h"

using namespace isotouch::core;
using namespace isotouch::servo;

namespace {
bool exact_zero(const Vec3& f) { return f.x == 0 && f.y == 0 && f.z == 0; }
}  // namespace

TEST(ForceGate, ThePeakIsTheSmallerOfTheScenesAndTheDevicesDirectionKept) {
  DeviceCaps caps;
  caps.max_force_n = 5.0;
  ForceLimits l = force_limits(caps, 3.3);
  EXPECT_EQ(l.peak_n, 3.3);
  l = force_limits(caps, 8.0);
  EXPECT_EQ(l.peak_n, 5.0);
  l = force_limits(DeviceCaps{}, INFINITY);
  EXPECT_TRUE(std::isinf(l.peak_n));
  EXPECT_TRUE(std::isinf(l.rate_n_per_s));  // nothing finite to derive a rate from

  ForceLimits only_peak;
  only_peak.peak_n = 3.3;
  ForceGate g(only_peak);
  std::uint8_t flags = 0;
  const Vec3 f = g.step({6, 0, 8}, 0.001, flags);
  EXPECT_NEAR(norm(f), 3.3, 1e-12);
  EXPECT_NEAR(f.x / f.z, 0.75, 1e-12);
  EXPECT_EQ(flags, kGatePeak);
  const Vec3 under = g.step({0, 3.2, 0}, 0.001, flags);
  EXPECT_EQ(under.y, 3.2);
  EXPECT_EQ(flags, 0);
}

TEST(ForceGate, TheRateLimitIsDerivedFromThePeakOrTheDevice) {
  DeviceCaps caps;
  caps.max_force_n = 3.3;
  EXPECT_NEAR(force_limits(caps, INFINITY).rate_n_per_s, 3.3 / kDefaultPeakRiseS, 1e-9);
  EXPECT_NEAR(force_limits(caps, 1.0).rate_n_per_s, 1.0 / kDefaultPeakRiseS, 1e-9);  // the scene's peak
  caps.max_force_rate_n_per_s = 400;
  EXPECT_EQ(force_limits(caps, 1.0).rate_n_per_s, 400);
  EXPECT_EQ(force_limits(caps, 1.0, 90).rate_n_per_s, 90);  // the servo's own setting first
  caps.max_continuous_force_n = 0.88;
  caps.continuous_window_s = 4;
  EXPECT_EQ(force_limits(caps, 1.0).continuous_n, 0.88);
  EXPECT_EQ(force_limits(caps, 1.0).continuous_window_s, 4);
}

// A step from 0 to 3 N at 1000 N/s and 1 ms ticks: 1, 2, 3 N; the direction of the change is
// the step's. A turn of the force's direction is a change too.
TEST(ForceGate, AStepDemandRisesAtTheRateLimit) {
  ForceLimits l;
  l.rate_n_per_s = 1000;
  ForceGate g(l);
  std::uint8_t flags = 0;
  for (int k = 1; k <= 5; ++k) {
    const Vec3 f = g.step({0, 0, 3}, 0.001, flags);
    EXPECT_NEAR(f.z, std::min(3.0, double(k)), 1e-12) << "tick " << k;
    EXPECT_EQ(f.x, 0);
    EXPECT_EQ(flags, k < 3 ? kGateRate : 0) << "tick " << k;
  }
  const Vec3 turned = g.step({3, 0, 0}, 0.001, flags);  // a 90 degree turn: |change| = 4.24 N
  EXPECT_NEAR(norm(turned - Vec3{0, 0, 3}), 1.0, 1e-12);
  EXPECT_EQ(flags, kGateRate);
  // A longer tick allows more: 2.5 ms -> 2.5 N.
  ForceGate h(l);
  EXPECT_NEAR(h.step({0, 0, 3}, 0.0025, flags).z, 2.5, 1e-12);
  // No time, no change.
  ForceGate z(l);
  EXPECT_TRUE(exact_zero(z.step({0, 0, 3}, 0, flags)));
  // With the servo's period as the cap (1 ms), a late 2.5 ms tick is allowed one period's 1 N.
  ForceLimits capped = l;
  capped.rate_dt_cap_s = 0.001;
  ForceGate c(capped);
  EXPECT_NEAR(c.step({0, 0, 3}, 0.0025, flags).z, 1.0, 1e-12);
}

// After a zero tick (a fault, a stale report, a stall) the force rises from 0 again, at the
// rate limit: no jump back to the force before it.
TEST(ForceGate, AfterAZeroTheForceRisesFromZeroAgain) {
  ForceLimits l;
  l.rate_n_per_s = 500;
  ForceGate g(l);
  std::uint8_t flags = 0;
  for (int k = 0; k < 20; ++k) g.step({0, 2, 0}, 0.001, flags);
  EXPECT_EQ(g.last_n().y, 2);
  g.zero(0.001);
  EXPECT_TRUE(exact_zero(g.last_n()));
  EXPECT_NEAR(g.step({0, 2, 0}, 0.001, flags).y, 0.5, 1e-12);
  EXPECT_EQ(flags, kGateRate);
}

// Non-finite demands: an exact zero at once (not a ramp down), flagged; finite after it
// rises from zero.
TEST(ForceGate, ANonFiniteDemandIsAnExactZeroAtOnce) {
  ForceLimits l;
  l.peak_n = 3.3;
  l.rate_n_per_s = 100;  // slow: a ramp down would take 20 ms
  ForceGate g(l);
  std::uint8_t flags = 0;
  for (int k = 0; k < 40; ++k) g.step({0, 0, 2}, 0.001, flags);
  ASSERT_EQ(g.last_n().z, 2);
  for (const Vec3 bad : {Vec3{NAN, 0, 1}, Vec3{0, 0, INFINITY}, Vec3{-INFINITY, 0, 0}}) {
    EXPECT_TRUE(exact_zero(g.step(bad, 0.001, flags)));
    EXPECT_TRUE(flags & kGateNonFinite);
  }
  EXPECT_NEAR(g.step({0, 0, 2}, 0.001, flags).z, 0.1, 1e-12);
  // A NaN time step allows no change (and is no NaN force).
  const Vec3 f = g.step({0, 0, 2}, NAN, flags);
  EXPECT_NEAR(f.z, 0.1, 1e-12);
}

// A drill held at the peak (3.3 N) against a continuous limit of 0.88 N over a 2 s window:
// the peak passes until the RMS reaches 0.88 N, at t* = -T ln(1 - (c / p)^2) (the exponential
// window's closed form), then (after one tick between the two, which brings the RMS to the
// limit exactly) |F| is held at 0.88 N and the RMS never exceeds it. Released,
// the window cools and the peak is allowed again.
TEST(ForceGate, TheContinuousLimitHoldsTheRmsOverItsWindow) {
  ForceLimits l;
  l.peak_n = 3.3;
  l.continuous_n = 0.88;
  l.continuous_window_s = 2.0;
  ForceGate g(l);
  const double dt = 0.001;
  const double t_star = -l.continuous_window_s * std::log(1 - (0.88 / 3.3) * (0.88 / 3.3));
  std::uint8_t flags = 0;
  int at_peak = 0, capped = 0, between = 0;
  double max_rms = 0;
  for (int k = 0; k < 20000; ++k) {  // 20 s
    const Vec3 f = g.step({0, 0, 5}, dt, flags);
    if (std::fabs(f.z - 3.3) < 1e-12) ++at_peak;
    if (std::fabs(f.z - 0.88) < 1e-12) ++capped;
    if (std::fabs(f.z - 3.3) >= 1e-12 && std::fabs(f.z - 0.88) >= 1e-12) ++between;
    max_rms = std::max(max_rms, g.rms_n());
  }
  EXPECT_NEAR(at_peak * dt, t_star, 2 * dt) << "t* " << t_star << " s";
  EXPECT_LE(between, 1);
  EXPECT_EQ(at_peak + capped + between, 20000);
  EXPECT_LE(max_rms, 0.88 * (1 + 1e-9)) << "the RMS passed the continuous limit";
  // Released for 3 windows: the RMS falls below the limit and the peak passes again.
  for (int k = 0; k < 6000; ++k) g.step({0, 0, 0}, dt, flags);
  EXPECT_LT(g.rms_n(), 0.88 * std::exp(-3.0 / 2) * 1.01);
  EXPECT_NEAR(g.step({0, 0, 5}, dt, flags).z, 3.3, 1e-12);
}

// Zero ticks cool the window as a zero force does.
TEST(ForceGate, ZeroTicksCoolTheWindow) {
  ForceLimits l;
  l.continuous_n = 1.0;
  l.continuous_window_s = 1.0;
  ForceGate a(l), b(l);
  std::uint8_t flags = 0;
  for (int k = 0; k < 500; ++k) a.step({0, 0, 0.9}, 0.001, flags), b.step({0, 0, 0.9}, 0.001, flags);
  for (int k = 0; k < 300; ++k) a.zero(0.001), b.step({}, 0.001, flags);
  EXPECT_NEAR(a.rms_n(), b.rms_n(), 1e-12);
  EXPECT_LT(a.rms_n(), 0.9 * std::sqrt(1 - std::exp(-0.5)));
}
