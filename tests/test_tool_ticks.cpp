// test_tool_ticks.cpp - serve's command thread: no burst of missed tool ticks, the tool
// applied over the time since its last tick (at most two periods), and a stroke that goes on
// through a contact lost for less than kStrokeGapS (service/tool_ticks.h). Clock values are
// given: nothing here waits.
#include <gtest/gtest.h>

#include <chrono>

#include "isotouch/service/tool_ticks.h"

namespace {

using isotouch::service::kStrokeGapS;
using isotouch::service::next_tick;
using isotouch::service::StrokeGap;
using isotouch::service::tool_dt;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// A thread that ran on time (or less than a period late) keeps its schedule; one that fell
// 1 s behind (60 periods at 60 Hz) runs its next tick a period from now: one tick, not 60.
TEST(ToolTicks, AThreadBehindRunsItsNextTickAPeriodFromNowNotABurst) {
  const Clock::time_point t0{};
  const auto period = milliseconds(16);
  EXPECT_EQ(next_tick(t0, t0, period), t0 + period);
  EXPECT_EQ(next_tick(t0, t0 + milliseconds(10), period), t0 + period);  // late, within a period
  EXPECT_EQ(next_tick(t0, t0 + period, period), t0 + period);  // a period late: the schedule kept
  const Clock::time_point now = t0 + milliseconds(1000);
  const Clock::time_point next = next_tick(t0, now, period);
  EXPECT_EQ(next, now + period);
  int ticks_due_by_now = 0;  // what a burst would run at once
  for (Clock::time_point t = next; t <= now; t = next_tick(t, now, period)) ++ticks_due_by_now;
  EXPECT_EQ(ticks_due_by_now, 0);
}

TEST(ToolTicks, TheToolIsAppliedOverTheTimeSinceItsLastTickAtMostTwoPeriods) {
  const double period = 1.0 / 60;
  EXPECT_DOUBLE_EQ(tool_dt(period, period), period);
  EXPECT_DOUBLE_EQ(tool_dt(0.5 * period, period), 0.5 * period);
  EXPECT_DOUBLE_EQ(tool_dt(1.0, period), 2 * period);  // a 1 s stall carves two periods' worth
  EXPECT_DOUBLE_EQ(tool_dt(-0.001, period), 0.0);
}

// At 60 Hz: 5 ticks out of contact (83 ms) and back: the same stroke; 6 ticks (100 ms) end it.
TEST(ToolTicks, AStrokeGoesOnThroughAContactLostForLessThanTheGap) {
  const double dt = 1.0 / 60;
  StrokeGap gap;
  for (int k = 0; k < 5; ++k) EXPECT_FALSE(gap.out_of_contact(dt)) << k;
  gap.in_contact();
  int ended_at = -1;
  for (int k = 0; k < 10 && ended_at < 0; ++k)
    if (gap.out_of_contact(dt)) ended_at = k;
  EXPECT_EQ(ended_at, 5);  // the 6th tick out: 6 / 60 s = kStrokeGapS
  EXPECT_NEAR(6 * dt, kStrokeGapS, 1e-12);
  // The count starts again after an end and after reset().
  for (int k = 0; k < 5; ++k) EXPECT_FALSE(gap.out_of_contact(dt)) << k;
  gap.reset();
  for (int k = 0; k < 5; ++k) EXPECT_FALSE(gap.out_of_contact(dt)) << k;
  EXPECT_TRUE(gap.out_of_contact(dt));
  // One long tick (the thread held 0.2 s, its dt clamped to two periods elsewhere) alone does not end it.
  StrokeGap slow;
  EXPECT_FALSE(slow.out_of_contact(tool_dt(0.2, dt)));
}

}  // namespace
