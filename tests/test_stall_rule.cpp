// The device side's stall rule (servo/stall_rule.h) on a simulated clock: a servo writing
// once a period (with jitter) and an output thread looking once a period of its own, at
// every servo rate from 1 to 10 kHz and output threads as fast as the servo or faster
// (vendor SDK threads) or polling (report devices, links). Judged by what the output thread
// was told to apply: the force is off within 3 servo periods of the last write, never
// before, the first write after a stall is a zero, and nothing non-finite passes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>

#include "isotouch/servo/stall_rule.h"

using namespace isotouch::core;
using namespace isotouch::servo;

namespace {
constexpr double kStallPeriods = 2.5;  // what ServoThread gives enable_force()

/// Servo at `servo_hz` writing 1 N for `writes` periods (each write up to `jitter` of a
/// period late), an output thread looking every `look_s` from `phase` of its period (0:
/// polling every 10 us). Returns the time from the last write to the first look that had the
/// force off [s], or -1 if none within 10 servo periods; `early` counts looks that had it
/// off while the servo was still writing (after the first write was seen), `stalls` the
/// rule's count.
struct SimRun {
  double off_after_s = -1;
  long early = 0;
  std::uint64_t stalls = 0;
};
SimRun simulate(double servo_hz, double look_s, double phase, double jitter, int writes = 200) {
  const auto ns = [](double s) { return std::int64_t(std::llround(s * 1e9)); };
  const double period = 1.0 / servo_hz;
  const double step = look_s > 0 ? look_s : 10e-6;
  StallRule rule;
  rule.enable(true, kStallPeriods * period, 0.01, 0, look_s);
  rule.restart(0);
  SimRun r;
  int k = 0;  // next write
  double last_write = -1;
  bool seen_on = false;
  // A deterministic jitter: each write late by a fraction of `jitter` that cycles.
  const auto write_time = [&](int i) { return (i + 1) * period + jitter * period * double((i * 7) % 10) / 10.0; };
  for (double t = phase * step + step; t < (writes + 12) * period; t += step) {
    while (k < writes && write_time(k) <= t) {
      last_write = write_time(k);
      rule.write({0, 0, 1}, std::uint64_t(k + 1), ns(last_write));
      ++k;
    }
    const StallLook l = rule.look(ns(t));
    if (l.on) seen_on = true;
    if (k < writes) {
      r.early += seen_on && !l.on && t > write_time(1);
    } else if (!l.on && r.off_after_s < 0) {
      r.off_after_s = t - last_write;
    }
  }
  r.stalls = rule.stalls();
  return r;
}
}  // namespace

TEST(StallRule, TheForceIsOffWithinThreeServoPeriodsAtEveryRate) {
  for (const double servo_hz : {1000.0, 2000.0, 4000.0, 10000.0}) {
    const double period = 1.0 / servo_hz;
    // Output threads as fast as the servo, faster, and polling (0).
    for (const double look_s : {period, period / 2, period / 4, 0.0}) {
      for (const double phase : {0.0, 0.25, 0.5, 0.9}) {
        const SimRun r = simulate(servo_hz, look_s, phase, 0.4);
        const std::string what = std::to_string(servo_hz) + " Hz servo, looks every " + std::to_string(look_s * 1e6) +
                                 " us, phase " + std::to_string(phase);
        ASSERT_GE(r.off_after_s, 0) << what << ": the force never went off";
        EXPECT_LE(r.off_after_s, 3 * period + 1e-9) << what << ": " << r.off_after_s / period << " periods";
        EXPECT_EQ(r.early, 0) << what << ": off while the servo wrote (late by up to 0.4 of a period)";
        EXPECT_EQ(r.stalls, 1u) << what;
      }
    }
  }
}

// Two periods without a write (one tick missed) is no stall, for a polling output thread
// (its stall time 2.5 periods) nor for one as fast as the servo (2 periods, not over 2); a
// silence a little longer is one for the latter (its force must be off within 3 periods).
TEST(StallRule, AMissedDeadlineIsNoStall) {
  for (const double look_frac : {0.0, 1.0}) {
    const double servo_hz = 1000, period = 1e-3;
    StallRule rule;
    rule.enable(true, kStallPeriods * period, 0.01, 0, look_frac * period);
    rule.restart(0);
    rule.write({0, 0, 1}, 1, 1'000'000);
    long off = 0;
    // The next write comes 2 periods later (one missed), looked at every period or polled.
    const double step = look_frac > 0 ? period : 10e-6;
    for (double t = 1e-3; t < 3e-3 + 1e-12; t += step) off += !rule.look(std::int64_t(t * 1e9 + 0.5)).on;
    rule.write({0, 0, 1}, 2, 3'000'000);
    off += !rule.look(3'000'001).on;
    EXPECT_EQ(off, 0) << "looks every " << look_frac << " periods at " << servo_hz << " Hz";
    EXPECT_EQ(rule.stalls(), 0u);
  }
}

// After a stall the force stays off until the servo writes after seeing the count, and that
// first write is itself a zero (no jump back to the force before the stall).
TEST(StallRule, TheFirstWriteAfterAStallIsAZero) {
  StallRule rule;
  const std::atomic<std::uint64_t>* count = rule.enable(true, 0.0025, 0.01, 0, 0);
  rule.restart(0);
  rule.write({0, 0, 2}, 1, 1'000'000);
  EXPECT_EQ(rule.look(1'000'100).force_n.z, 2);
  const StallLook stalled = rule.look(4'000'000);  // 3 ms without a write
  EXPECT_TRUE(stalled.stalled_now);
  EXPECT_FALSE(stalled.on);
  EXPECT_EQ(count->load(), 1u);
  rule.write({0, 0, 2}, 2, 4'100'000);  // the servo's first write after it: stored as zero
  StallLook l = rule.look(4'200'000);
  EXPECT_TRUE(l.on);
  EXPECT_EQ(l.force_n.z, 0.0);
  rule.write({0, 0, 0.5}, 3, 5'100'000);  // then whatever the servo ramps in
  l = rule.look(5'200'000);
  EXPECT_EQ(l.force_n.z, 0.5);
}

TEST(StallRule, NonFiniteForcesAreZerosAndNothingBeforeEnable) {
  StallRule rule;
  rule.restart(0);
  rule.write({0, 0, 1}, 1, 100);
  EXPECT_FALSE(rule.look(200).on) << "not enabled";
  rule.enable(true, 0.0025, 0.01, 1000, 0);
  EXPECT_FALSE(rule.look(1100).on) << "the write was made before the enable";
  for (const Vec3 bad : {Vec3{NAN, 0, 0}, Vec3{0, INFINITY, 0}, Vec3{0, 0, -INFINITY}}) {
    rule.write(bad, 2, 2000);
    const StallLook l = rule.look(2100);
    EXPECT_TRUE(l.on);
    EXPECT_TRUE(l.force_n.x == 0 && l.force_n.y == 0 && l.force_n.z == 0);
  }
  rule.disable();
  rule.write({0, 0, 1}, 3, 3000);
  EXPECT_FALSE(rule.look(3100).on);
}
