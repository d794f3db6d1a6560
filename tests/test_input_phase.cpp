// The servo's ticks follow a link's inputs (servo/input_phase.h): judged on simulated clocks,
// against the arrival times the test itself generated.
#include "isotouch/servo/input_phase.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <vector>

namespace {
using isotouch::servo::ArrivalClock;
using isotouch::servo::follow_input_phase;
using isotouch::servo::InputPhase;

constexpr std::int64_t kMs = 1'000'000;

/// A deterministic jitter in [0, max_ns): arrivals are only ever delayed.
struct Jitter {
  std::uint64_t s = 12345;
  std::int64_t next(std::int64_t max_ns) {
    s = s * 6364136223846793005ULL + 1442695040888963407ULL;
    return std::int64_t((s >> 33) % std::uint64_t(max_ns));
  }
};

/// The first servo tick at or after `t` (the one that renders an input arriving at `t`);
/// each deadline is chosen at the tick before it, from the phase known then.
struct Servo {
  std::int64_t next, period, lead;
  bool follow = true;
  std::int64_t first_tick_after(std::int64_t t, const ArrivalClock& c, std::vector<std::int64_t>* steps = nullptr) {
    while (next < t) {
      std::int64_t n = next + period;
      if (follow) n = follow_input_phase(n, period, c.phase(), lead);
      if (steps) steps->push_back(n - next);
      next = n;
    }
    return next;
  }
};

TEST(ArrivalClock, LearnsTheStreamsPeriodAndItsEarliestPhaseThroughJitter) {
  ArrivalClock c;
  Jitter j;
  EXPECT_LT(c.phase().due_ns, 0) << "due before any input";
  const std::int64_t t0 = 5 * kMs, latency = 40'000;
  int late = 0;  // predictions later than the earliest arrivals' phase + 40 us (one arrival's jitter kept)
  for (int k = 0; k < 400; ++k) {
    c.arrived(t0 + k * kMs + latency + j.next(80'000));
    if (k >= 50 && c.phase().due_ns > t0 + (k + 1) * kMs + latency + 40'000) ++late;
  }
  // Taken from each arrival, half the predictions would be late (the jitter is uniform).
  EXPECT_LT(late, 350 / 4) << "of 350 predictions: the phase follows each arrival's jitter";
  const InputPhase p = c.phase();
  EXPECT_NEAR(double(p.period_ns), double(kMs), 0.01 * kMs);
  // The next pose is sent at t0 + 400 ms and arrives 40-120 us later.
  const std::int64_t sent = t0 + 400 * kMs;
  EXPECT_GE(p.due_ns, sent + latency - 20'000);
  EXPECT_LE(p.due_ns, sent + latency + 60'000);
}

TEST(ArrivalClock, AGapIsNoPhaseAndANewRateIsLearnedAgain) {
  ArrivalClock c;
  std::int64_t t = 0;
  for (int k = 0; k < 50; ++k) c.arrived(t += kMs);
  c.arrived(t += 10 * kMs);  // a 10 ms gap
  EXPECT_LT(c.phase().due_ns, 0) << "a gap still predicting the old phase";
  for (int k = 0; k < 20; ++k) c.arrived(t += 4 * kMs);  // now 250 Hz
  EXPECT_NEAR(double(c.phase().period_ns), 4.0 * kMs, 0.01 * kMs);
  EXPECT_EQ(c.phase().due_ns, t + 4 * kMs);
}

TEST(FollowInputPhase, TheTickMovesToTheLeadAfterEachArrivalInSmallSteps) {
  ArrivalClock c;
  Jitter j;
  const std::int64_t lead = 100'000;
  // The worst phase: each pose arrives 0.1 ms after a tick, so it waits 0.9 ms.
  Servo s{0, kMs, lead}, fixed{0, kMs, lead, false};
  std::vector<std::int64_t> steps;
  std::vector<std::int64_t> wait_follow, wait_fixed;
  for (int k = 1; k <= 200; ++k) {
    const std::int64_t arrival = k * kMs + 100'000 + j.next(30'000);
    c.arrived(arrival);
    wait_follow.push_back(s.first_tick_after(arrival, c, &steps) - arrival);
    wait_fixed.push_back(fixed.first_tick_after(arrival, c) - arrival);
  }
  for (std::int64_t d : steps) {
    EXPECT_GE(d, kMs - kMs / 16) << "a servo period shortened by more than 1/16";
    EXPECT_LE(d, kMs + kMs / 16) << "a servo period lengthened by more than 1/16";
  }
  for (std::size_t k = 20; k < wait_follow.size(); ++k) {
    EXPECT_LE(wait_follow[k], lead + 30'000) << "pose " << k << " waited for the servo";
    EXPECT_GE(wait_fixed[k], 800'000) << "pose " << k << ": the fixed-phase servo is not the worst case";
  }
}

TEST(FollowInputPhase, ASlowerStreamIsFollowedAtAWholeMultipleAndNotOtherwise) {
  const std::int64_t lead = 100'000;
  for (const std::int64_t input : {10 * kMs, 3'333'333L, 1'020'000L}) {
    ArrivalClock c;
    Servo s{0, kMs, lead};
    std::int64_t worst = 0;
    for (int k = 1; k <= 100; ++k) {
      const std::int64_t arrival = k * input + 550'000;
      c.arrived(arrival);
      if (k > 20) worst = std::max(worst, s.first_tick_after(arrival, c) - arrival);
      else s.first_tick_after(arrival, c);
    }
    if (input == 10 * kMs) {
      EXPECT_LE(worst, lead + 1'000) << "a 100 Hz stream on a 1 kHz servo not followed";
    } else {  // 300 Hz, or 2 % slower than the servo: followed, the servo's rate would change
      EXPECT_EQ(s.next % kMs, 0) << "the servo followed a stream it cannot stay aligned with";
    }
  }
}

TEST(FollowInputPhase, NothingMovesWithoutAnInputOrAfterItPaused) {
  EXPECT_EQ(follow_input_phase(7 * kMs, kMs, InputPhase{}, 100'000), 7 * kMs);
  const InputPhase old{2 * kMs + 500'000, kMs};
  EXPECT_EQ(follow_input_phase(20 * kMs, kMs, old, 100'000), 20 * kMs) << "followed a stream paused for 17 periods";
  EXPECT_NE(follow_input_phase(4 * kMs, kMs, old, 100'000), 4 * kMs);
}

}  // namespace

/// Arrivals at 1 kHz with 0-30 us of jitter, and every 40th (2.5 %) 300 us late: how many
/// poses of `n` the next one overtakes (arrives before the servo tick that renders it) once the
/// clock has seen 300 arrivals, and the largest wait of an on-time pose then [ns].
struct Overtaken {
  int poses = 0, overtaken = 0;
  std::int64_t on_time_wait = 0;
};
Overtaken run_late_stream(bool use_lateness, int n) {
  ArrivalClock c;
  Jitter j;
  std::vector<std::int64_t> a(std::size_t(n) + 1);
  for (int k = 0; k <= n; ++k) a[std::size_t(k)] = (k + 1) * kMs + j.next(30'000) + (k % 40 == 39 ? 300'000 : 0);
  Servo s{0, kMs, 100'000};
  Overtaken o;
  for (int k = 0; k < n; ++k) {
    c.arrived(a[std::size_t(k)]);
    std::int64_t tick = s.next;
    while (tick < a[std::size_t(k)]) {  // as Servo::first_tick_after, with the lateness kept or not
      InputPhase p = c.phase();
      if (!use_lateness) p.late_ns = 0;
      tick = s.next = follow_input_phase(s.next + kMs, kMs, p, s.lead);
    }
    if (k < 300) continue;
    ++o.poses;
    if (a[std::size_t(k) + 1] <= tick) ++o.overtaken;
    if (k % 40 != 39) o.on_time_wait = std::max(o.on_time_wait, tick - a[std::size_t(k)]);
  }
  return o;
}

TEST(FollowInputPhase, TheLeadGrowsToCoverLateArrivalsSoFewArePassedOver) {
  const Overtaken fixed = run_late_stream(false, 2300), adaptive = run_late_stream(true, 2300);
  // With a fixed 100 us lead each 300 us late pose misses its tick and the next overtakes it.
  EXPECT_GE(fixed.overtaken, fixed.poses / 50) << "the case does not test late arrivals";
  EXPECT_LE(adaptive.overtaken, adaptive.poses / 200) << "of " << adaptive.poses << " poses";
  // The price: on-time poses wait up to the grown lead (~300 us + margin), not a period, and
  // after a late pose up to 1/8 of its lateness more (the anchor is pulled 1/8 of the way to
  // each arrival, and the ticks follow it).
  EXPECT_LE(adaptive.on_time_wait, 300'000 + 2 * isotouch::servo::ArrivalClock::kLateBinNs +
                                       isotouch::servo::kLateMarginNs + 30'000 + 300'000 / 8);
}

TEST(ArrivalClock, TheLatenessIsTheWindowsHighPercentileAndForgetsOldArrivals) {
  ArrivalClock c;
  std::int64_t t = 0;
  for (int k = 0; k < 300; ++k) c.arrived(t += kMs);
  EXPECT_LE(c.phase().late_ns, ArrivalClock::kLateBinNs) << "a steady stream is not late";
  for (int k = 0; k < 300; ++k) c.arrived(t += kMs + (k % 20 == 0 ? 200'000 : 0) - (k % 20 == 1 ? 200'000 : 0));
  EXPECT_GE(c.phase().late_ns, 150'000) << "5 % of arrivals 200 us late are in the 99.5th percentile";
  EXPECT_LE(c.phase().late_ns, 210'000);
  for (int k = 0; k < 300; ++k) c.arrived(t += kMs);
  EXPECT_LE(c.phase().late_ns, ArrivalClock::kLateBinNs) << "the window holds old arrivals";
}

TEST(ArrivalClock, OneLateArrivalIn256IsOutsideThePercentileTwoAreIn) {
  for (const int late : {1, 2}) {
    ArrivalClock c;
    std::int64_t t = 0;
    for (int k = 0; k < 256; ++k) c.arrived(t += kMs);
    for (int k = 0; k < 256; ++k) {
      const bool slow = k % 128 == 50 && k / 128 < late;
      c.arrived(t += kMs + (slow ? 300'000 : 0) - (k % 128 == 51 && (k - 1) / 128 < late ? 300'000 : 0));
    }
    if (late == 1) EXPECT_LE(c.phase().late_ns, ArrivalClock::kLateBinNs) << "one arrival in 256 is the 99.6th percentile's outlier";
    else EXPECT_GE(c.phase().late_ns, 250'000) << "two arrivals in 256 are within the 99.5th percentile";
  }
}

TEST(ArrivalClock, ArrivalsOverHalfAPeriodLateCountAndANewStreamForgetsThem) {
  ArrivalClock c;
  std::int64_t t = 0;
  for (int k = 0; k < 300; ++k) c.arrived(t += kMs + (k % 20 == 0 ? 600'000 : 0) - (k % 20 == 1 ? 600'000 : 0));
  EXPECT_GE(c.phase().late_ns, 550'000) << "arrivals 0.6 period late are the lateness the lead must cover";
  for (int k = 0; k < 20; ++k) c.arrived(t += 4 * kMs);  // the stream restarts at 250 Hz
  EXPECT_LE(c.phase().late_ns, ArrivalClock::kLateBinNs) << "the old stream's lateness kept";
}

namespace {
using isotouch::servo::input_wait_until;

TEST(InputWaitUntil, ATickWaitsForItsLateInputUntilHalfAPeriodPastItsDeadlineOnly) {
  const InputPhase due_now{10 * kMs, kMs};
  // The tick 100 us after the input was due, which has not arrived: wait up to 10.6 ms.
  EXPECT_EQ(input_wait_until(10 * kMs + 100'000, 10 * kMs + 100'000, kMs, due_now), 10 * kMs + 600'000);
  // Arrived (the clock moved its due time a period on): no wait.
  EXPECT_EQ(input_wait_until(10 * kMs + 100'000, 10 * kMs + 100'000, kMs, InputPhase{11 * kMs, kMs}), -1);
  // Due over a servo period ago: the input paused, no tick waits for it.
  EXPECT_EQ(input_wait_until(11 * kMs + 100'001, 11 * kMs + 100'001, kMs, due_now), -1);
  // Past the wait's end already, unknown phase, a period the servo cannot follow: no wait.
  EXPECT_EQ(input_wait_until(10 * kMs + 600'000, 10 * kMs + 100'000, kMs, due_now), -1);
  EXPECT_EQ(input_wait_until(10 * kMs + 100'000, 10 * kMs + 100'000, kMs, InputPhase{}), -1);
  EXPECT_EQ(input_wait_until(10 * kMs + 100'000, 10 * kMs + 100'000, kMs, InputPhase{10 * kMs, 1'300'000}), -1);
  // A 500 Hz input on a 1 kHz servo: the tick after its due time waits, the one between does not.
  EXPECT_EQ(input_wait_until(10 * kMs + 100'000, 10 * kMs + 100'000, kMs, InputPhase{10 * kMs, 2 * kMs}),
            10 * kMs + 600'000);
  EXPECT_EQ(input_wait_until(11 * kMs + 100'000, 11 * kMs + 100'000, kMs, InputPhase{12 * kMs, 2 * kMs}), -1);
}

/// Arrivals at 1 kHz with 0-30 us of jitter and every 40th `late_ns` late, a servo at 1 kHz
/// following them with a fixed 100 us lead (the lateness percentile off, so only the wait can
/// catch a late pose): how many of the poses after the first 300 no tick renders while it is
/// the newest (overtaken), and the longest time from an arrival to the tick rendering it [ns].
struct Waited {
  int poses = 0, overtaken = 0;
  std::int64_t longest = 0;
};
Waited run_waiting_stream(bool wait, std::int64_t late_ns, int n = 2000, std::int64_t next_late_ns = 0) {
  Jitter j;
  std::vector<std::int64_t> a(std::size_t(n) + 1);
  for (int k = 0; k <= n; ++k)
    a[std::size_t(k)] = (k + 1) * kMs + j.next(30'000) + (k % 40 == 39 ? late_ns : 0) + (k % 40 == 0 && k > 0 ? next_late_ns : 0);
  ArrivalClock c;
  int fed = 0;  // arrivals the clock has seen: those at or before the time fed up to
  auto feed = [&](std::int64_t t) {
    while (fed <= n && a[std::size_t(fed)] <= t) c.arrived(a[std::size_t(fed++)]);
  };
  std::vector<std::int64_t> rendered(std::size_t(n) + 1, -1);  // the first tick rendering each pose
  std::int64_t next = 0;
  while (fed <= n) {
    InputPhase p = c.phase();
    p.late_ns = 0;
    next = follow_input_phase(next + kMs, kMs, p, 100'000);
    feed(next);
    std::int64_t t = next;
    const std::int64_t until = wait ? input_wait_until(t, next, kMs, c.phase()) : -1;
    if (until > t) {  // the servo spins until the input arrives or the wait ends
      t = fed <= n && a[std::size_t(fed)] <= until ? a[std::size_t(fed)] : until;
      feed(t);
    }
    if (fed > 0 && rendered[std::size_t(fed - 1)] < 0) rendered[std::size_t(fed - 1)] = t;
  }
  Waited w;
  for (int k = 300; k < n; ++k) {
    ++w.poses;
    if (rendered[std::size_t(k)] < 0) ++w.overtaken;
    else w.longest = std::max(w.longest, rendered[std::size_t(k)] - a[std::size_t(k)]);
  }
  return w;
}

TEST(InputWaitUntil, ALatePoseIsRenderedWhenItArrivesNotOvertaken) {
  const Waited no_wait = run_waiting_stream(false, 400'000), waited = run_waiting_stream(true, 400'000);
  // Without the wait each 400 us late pose misses its tick (100 us after it was due) and the
  // next pose overtakes it: 1 in 40.
  EXPECT_GE(no_wait.overtaken, no_wait.poses / 45) << "the case does not test late arrivals";
  EXPECT_EQ(waited.overtaken, 0) << "of " << waited.poses << " poses";
  // Each pose rendered within the lead and the jitter of its arrival (a late one at once).
  EXPECT_LE(waited.longest, 100'000 + 30'000 + kMs / 16);
  // Later than the wait's end (half a period past the tick): overtaken as before, and the
  // other poses unharmed.
  const Waited too_late = run_waiting_stream(true, 800'000);
  EXPECT_LE(too_late.overtaken, too_late.poses / 35);
}

// Two late poses in a row (every 40th 300 us late, and the one after it too): each tick waits
// for its pose, the second's too. Before, the first late arrival moved the learned period 2 %
// (a running mean of 16 intervals), past the 0.5 % within which ticks follow and wait, and
// every second late pose was overtaken: 42 of 1700.
TEST(InputWaitUntil, TwoLatePosesInARowAreBothRendered) {
  for (const std::int64_t first : {100'000, 300'000, 400'000}) {
    const Waited w = run_waiting_stream(true, first, 2000, 300'000);
    EXPECT_EQ(w.overtaken, 0) << "of " << w.poses << " poses, the first of each pair " << first / 1000 << " us late";
    // As ALatePoseIsRenderedWhenItArrivesNotOvertaken's, and the anchor's pull toward a late
    // arrival (1/8 of its lateness) that the next ticks follow.
    EXPECT_LE(w.longest, 100'000 + 30'000 + kMs / 16 + std::max<std::int64_t>(first, 300'000) / 8);
  }
}

}  // namespace
