// The time-domain passivity observer/controller at a device port (servo/port_passivity.h),
// against energies and dampings worked out by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "isotouch/servo/port_passivity.h"

using isotouch::core::Vec3;
using isotouch::servo::PortPassivity;

// A held force of 1 N along +x while the device moves +1 mm per 1 ms tick (1 m/s): the
// force does 1 mJ of work on the user per tick, which the user never put in.
TEST(PortPassivity, DampsExactlyTheEnergyTheHeldForceWouldHandOut) {
  PortPassivity pc(true, 100, 10);
  const Vec3 f{1, 0, 0};
  EXPECT_EQ(pc.step(0.000, {0, 0, 0}, f).x, 1.0);  // first tick: no velocity yet
  // E_out = 1 mJ; with the next tick's 1 mJ the excess is 2 mJ: alpha = 2e-3 / (1e-3 * 1^2) = 2.
  const Vec3 a = pc.step(0.001, {0.001, 0, 0}, f);
  EXPECT_NEAR(pc.energy_out_j(), 1e-3, 1e-15);
  EXPECT_NEAR(pc.alpha(), 2.0, 1e-12);
  EXPECT_NEAR(a.x, -1.0, 1e-12);
  // The held -1 N over +1 mm: E_in = 1 mJ, the damper took 2 mJ; excess 1 + 1 - 1 mJ: alpha 1.
  const Vec3 b = pc.step(0.002, {0.002, 0, 0}, f);
  EXPECT_NEAR(pc.energy_in_j(), 1e-3, 1e-15);
  EXPECT_NEAR(pc.dissipated_j(), 2e-3, 1e-15);
  EXPECT_NEAR(pc.alpha(), 1.0, 1e-12);
  EXPECT_NEAR(b.x, 0.0, 1e-12);
  EXPECT_EQ(pc.active_ticks(), 2);
}

TEST(PortPassivity, VelocityIsTakenOnTheDevicesClock) {
  PortPassivity pc(true, 100, 10);
  const Vec3 f{1, 0, 0};
  pc.step(0.000, {0, 0, 0}, f, 0);
  // 1 mm in 2 ms (a late report): v = 0.5 m/s, E_out = 1 mJ, next-tick work 1 * 0.5 * 2 ms
  // = 1 mJ: alpha = 2e-3 / (2e-3 * 0.25) = 4.
  pc.step(0.002, {0.001, 0, 0}, f, 0);
  EXPECT_NEAR(pc.alpha(), 4.0, 1e-12);
}

TEST(PortPassivity, ObservesWithoutActingWhenDisabledAndClipsAtTheLimits) {
  PortPassivity off(false, 100, 10);
  off.step(0.000, {0, 0, 0}, {1, 0, 0}, 0);
  EXPECT_EQ(off.step(0.001, {0.001, 0, 0}, {1, 0, 0}, 0).x, 1.0);
  EXPECT_NEAR(off.energy_out_j(), 1e-3, 1e-15);
  EXPECT_EQ(off.active_ticks(), 0);
  PortPassivity capped(true, 0.5, 10);
  capped.step(0.000, {0, 0, 0}, {1, 0, 0}, 0);
  EXPECT_NEAR(capped.step(0.001, {0.001, 0, 0}, {1, 0, 0}, 0).x, 0.5, 1e-12);  // alpha_max = 0.5
  PortPassivity sat(false, 100, 2);
  EXPECT_NEAR(sat.step(0.000, {0, 0, 0}, {3, 4, 0}, 0).y, 1.6, 1e-12);  // |F| 5 N clipped to 2 N
  EXPECT_EQ(sat.step(0.001, {NAN, 0, 0}, {3, 4, 0}, 0).y, 0.0);          // bad input: zero force
}

// A device clock that repeats or steps back still moved the device: the held force's work
// (f . dx, no dt in it) must reach the energies.
TEST(PortPassivity, MotionOnARepeatedOrBackwardTimestampIsStillCounted) {
  PortPassivity pc(false, 100, 10);
  const Vec3 f{1, 0, 0};
  pc.step(0.001, {0, 0, 0}, f);
  pc.step(0.001, {0.001, 0, 0}, f);  // repeated t: +1 mm along the 1 N force, 1 mJ out
  EXPECT_NEAR(pc.energy_out_j(), 1e-3, 1e-15);
  pc.step(0.0005, {0, 0, 0}, f);  // backward t: -1 mm against it, 1 mJ in
  EXPECT_NEAR(pc.energy_in_j(), 1e-3, 1e-15);
}

// Bad settings are refused by name and value: a NaN, zero or negative force limit would
// leave the force unclipped, a NaN or negative alpha_max the damping uncapped or active.
TEST(PortPassivity, RejectsSettingsThatWouldLeaveTheForceUnbounded) {
  auto message = [](double alpha_max, double limit) {
    try {
      PortPassivity pc(true, alpha_max, limit);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message(40, NAN).find("force_limit_n = nan"), std::string::npos) << message(40, NAN);
  EXPECT_NE(message(40, 0).find("force_limit_n = 0"), std::string::npos) << message(40, 0);
  EXPECT_NE(message(40, -1).find("force_limit_n = -1"), std::string::npos) << message(40, -1);
  EXPECT_NE(message(NAN, 10).find("alpha_max = nan"), std::string::npos) << message(NAN, 10);
  EXPECT_NE(message(-1, 10).find("alpha_max = -1"), std::string::npos) << message(-1, 10);
  EXPECT_EQ(message(0, 10), "accepted");  // no damping at all is a valid (observing) setting
}

// An infinite timestamp is bad input like a NaN one: zero force, and the next sane tick
// starts afresh (it passed t == t and the held force went out undamped).
TEST(PortPassivity, InfiniteTimestampGivesZeroForce) {
  PortPassivity pc(true, 100, 10);
  const Vec3 f{1, 0, 0};
  pc.step(0.000, {0, 0, 0}, f);
  EXPECT_EQ(pc.step(INFINITY, {0.001, 0, 0}, f).x, 0.0);
  EXPECT_EQ(pc.step(-INFINITY, {0.002, 0, 0}, f).x, 0.0);
  EXPECT_EQ(pc.step(0.003, {0.003, 0, 0}, f).x, 1.0);  // first tick again: no velocity yet
  EXPECT_EQ(pc.energy_out_j(), 0.0);
}

// At the cap the damping is alpha_max v, with v over the device's own period: 1 mm in 2 ms
// is 0.5 m/s, and alpha_max = 0.5 N s/m takes 0.25 N off the held 1 N (0.5 N if the
// period were taken as 1 ms).
TEST(PortPassivity, CappedDampingUsesTheDevicesPeriod) {
  PortPassivity pc(true, 0.5, 10);
  const Vec3 f{1, 0, 0};
  pc.step(0.000, {0, 0, 0}, f);
  EXPECT_NEAR(pc.step(0.002, {0.001, 0, 0}, f).x, 0.75, 1e-12);
  EXPECT_NEAR(pc.alpha(), 0.5, 1e-12);
}

// The damping's share of a clipped force is booked, not the damping asked for: a -9 N
// damping on a 3 N request, clipped from -6 N to the 1 N limit (factor 1/6), holds -1.5 N
// of damping; over the next +1 mm that takes out 1.5 mJ (9 mJ was booked before).
TEST(PortPassivity, DissipationIsBookedAfterTheClip) {
  PortPassivity pc(true, 100, 1);
  const Vec3 f{3, 0, 0};
  const double e_ref = -5e-3;  // two-port reference: the far side took 5 mJ out
  pc.step(0.000, {0, 0, 0}, f, e_ref);  // clipped to 1 N, no damping yet
  // E_out 1 mJ, next tick's 3 mJ, reference -5 mJ: excess 9 mJ, per metre 9 mJ / (1 mm)^2.
  EXPECT_NEAR(pc.step(0.001, {0.001, 0, 0}, f, e_ref).x, -1.0, 1e-12);
  pc.step(0.002, {0.002, 0, 0}, f, e_ref);
  EXPECT_NEAR(pc.dissipated_j(), 1.5e-3, 1e-15);
}
