// The frame-budget controller (engine/frame_budget.h), judged with injected frame costs from
// a cost model the test defines (a fixed part plus a part per pixel), no wall clock.
#include "isotouch/engine/frame_budget.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace {
using isotouch::engine::FrameBudget;
using isotouch::engine::FrameBudgetOptions;

/// A frame drawn whole at `scale` costs fixed + per_full * scale^2 [ms], +-noise (deterministic).
struct CostModel {
  double fixed_ms, per_full_ms, noise = 0.0;
  unsigned s = 7;
  double cost(double scale) {
    s = s * 1103515245u + 12345u;
    const double u = double((s >> 8) & 0xffff) / 65535.0 * 2 - 1;  // [-1, 1]
    return (fixed_ms + per_full_ms * scale * scale) * (1 + noise * u);
  }
};

/// Moving frames: the cost of each, drawn at the controller's scale.
std::vector<double> moving_frames(FrameBudget& fb, CostModel& m, int n, std::vector<double>* scales = nullptr) {
  std::vector<double> costs;
  for (int k = 0; k < n; ++k) {
    const double s = fb.moving_scale();
    const double c = m.cost(s);
    fb.measured_whole(s, c);
    costs.push_back(c);
    if (scales) scales->push_back(s);
  }
  return costs;
}

TEST(FrameBudget, MovingFramesHoldTheBudgetWithin1_2xAfterFiveFrames) {
  for (const CostModel base : {CostModel{2, 60}, CostModel{8, 90, 0.1}, CostModel{1, 250, 0.15}, CostModel{0.5, 20}}) {
    CostModel m = base;
    FrameBudget fb(FrameBudgetOptions{33, 0.125});
    const std::vector<double> c = moving_frames(fb, m, 40);
    for (std::size_t k = 5; k < c.size(); ++k)
      EXPECT_LE(c[k], 1.2 * 33) << "frame " << k << " of a " << base.fixed_ms << " + " << base.per_full_ms << " ms model";
    // Not needlessly coarse: a frame that fits at scale 1 is drawn at 1; else it uses the budget.
    if (base.fixed_ms + base.per_full_ms <= 0.9 * 33 * 0.9) {
      EXPECT_EQ(fb.moving_scale(), 1.0);
    } else {
      EXPECT_GE(c.back(), 0.6 * 33) << "a " << base.per_full_ms << " ms frame drawn far below the budget";
    }
  }
}

TEST(FrameBudget, RecoversWithinFiveFramesAfterACostStep) {
  CostModel m{2, 60};
  FrameBudget fb(FrameBudgetOptions{33, 0.125});
  moving_frames(fb, m, 20);
  for (const double step : {4.0, 0.25}) {  // the view zooms in (4x the pixels hit), then back out
    m.per_full_ms *= step;
    const std::vector<double> c = moving_frames(fb, m, 20);
    for (std::size_t k = 5; k < c.size(); ++k) EXPECT_LE(c[k], 1.2 * 33) << "frame " << k << " after a x" << step << " step";
    EXPECT_GE(c.back(), 0.6 * 33) << "after a x" << step << " step the scale did not come back up";
  }
}

TEST(FrameBudget, AFixedPartIsLeftOutOfTheScaling) {
  // 12 ms that no scale changes (the upscale, submission) and 80 ms of pixels at scale 1:
  // told the fixed part, the controller fits the rest into the target.
  CostModel m{12, 80};
  FrameBudget fb(FrameBudgetOptions{33, 0.125});
  for (int k = 0; k < 20; ++k) {
    const double s = fb.moving_scale(), c = m.cost(s);
    fb.measured_whole(s, c, m.fixed_ms);
  }
  const double s = fb.moving_scale();
  EXPECT_LE(m.cost(s), 33.0);
  EXPECT_GE(m.cost(s), 0.8 * 0.9 * 33) << "scale " << s << " leaves the budget unused";
  // A fixed part above the target: the cheapest frame there is, and no division by <= 0.
  FrameBudget over(FrameBudgetOptions{33, 0.25});
  over.measured_whole(0.5, 45, 40);
  EXPECT_EQ(over.moving_scale(), 0.25);
}

TEST(FrameBudget, NoBudgetOrNoMeasurementDrawsWhole) {
  FrameBudget none(FrameBudgetOptions{0});
  none.measured_whole(1.0, 500);
  EXPECT_EQ(none.moving_scale(), 1.0);
  FrameBudget fresh;
  EXPECT_EQ(fresh.moving_scale(), 1.0);
  fresh.measured_whole(0.5, std::nan(""));
  fresh.measured_whole(0.0, 10);
  EXPECT_EQ(fresh.full_cost_ms(), 0.0) << "a cost that is not a number was learned";
  FrameBudget floor(FrameBudgetOptions{33, 0.25});
  floor.measured_whole(1.0, 10000);
  EXPECT_EQ(floor.moving_scale(), 0.25) << "below the smallest scale";
}

}  // namespace
