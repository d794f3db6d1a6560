// The still view's band planner (engine/refine_bands.h), judged with injected band costs from
// a cost model the test defines (a fixed part per band plus a part per hit pixel and per miss
// at full resolution), no wall clock.
#include "isotouch/engine/refine_bands.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

namespace {
using isotouch::engine::FrameBudget;
using isotouch::engine::FrameBudgetOptions;
using isotouch::engine::RefineBands;

/// A picture W x H whose rows [obj0, obj1) hit the object over `cover` of their width.
struct Scene {
  int W, H, obj0, obj1;
  double cover;
  bool hit(int x, int y) const { return y >= obj0 && y < obj1 && x < int(cover * W); }
  /// The last moving frame's depth at lw x lh (nearest row and column).
  std::vector<float> low(int lw, int lh) const {
    std::vector<float> d(std::size_t(lw) * std::size_t(lh));
    for (int y = 0; y < lh; ++y)
      for (int x = 0; x < lw; ++x) d[std::size_t(y * lw + x)] = hit(x * W / lw, y * H / lh) ? 1.0f : -1.0f;
    return d;
  }
  /// A band's cost [ms]: fixed + per pixel (a hit costs 5x a miss).
  double band_ms(int y0, int n, double fixed, double per_hit) const {
    double c = fixed;
    for (int y = y0; y < y0 + n; ++y)
      for (int x = 0; x < W; ++x) c += per_hit * (hit(x, y) ? 1.0 : 0.2);
    return c;
  }
};

/// The bands' rows and costs until done (at most 10 * H bands).
struct Bands {
  std::vector<int> y0, rows;
  std::vector<double> ms;
};
Bands refine(const Scene& s, const FrameBudget& fb, double fixed, double per_hit) {
  RefineBands bands(s.low(s.W / 2, s.H / 2), s.W / 2, s.H / 2, s.H, fb);
  Bands r;
  while (!bands.done() && int(r.rows.size()) < 10 * s.H) {
    const int y = bands.next_row(), n = bands.next_rows();
    const double ms = s.band_ms(y, n, fixed, per_hit);
    r.y0.push_back(y);
    r.rows.push_back(n);
    r.ms.push_back(ms);
    bands.drawn(ms);
  }
  return r;
}

FrameBudget learned_budget(double budget_ms, double fixed_ms) {
  FrameBudget fb(FrameBudgetOptions{budget_ms});
  fb.measured_whole(0.5, fixed_ms + 10, fixed_ms);  // the moving frames' fixed part
  return fb;
}

TEST(RefineBands, BandsCoverThePictureInOrderOnce) {
  const Scene s{640, 480, 100, 380, 0.7};
  const Bands r = refine(s, learned_budget(33, 2), 2, 3e-4);
  ASSERT_FALSE(r.rows.empty());
  int next = 0;
  for (std::size_t k = 0; k < r.rows.size(); ++k) {
    EXPECT_EQ(r.y0[k], next) << "band " << k;
    EXPECT_GE(r.rows[k], 1);
    next += r.rows[k];
  }
  EXPECT_EQ(next, s.H);
}

TEST(RefineBands, EveryBandAfterTheFirstFitsTheBudgetAndAtMostSixteenFrames) {
  // Full frames of 30-150 ms: each is spread over frames of at most the 33 ms budget.
  for (const double per_hit : {1e-4, 2e-4, 5e-4}) {
    const Scene s{640, 480, 60, 420, 0.8};
    const double full = s.band_ms(0, s.H, 0, per_hit);
    const Bands r = refine(s, learned_budget(33, 2), 2, per_hit);
    SCOPED_TRACE("full frame " + std::to_string(full) + " ms");
    for (std::size_t k = 1; k < r.ms.size(); ++k) EXPECT_LE(r.ms[k], 33.0) << "band " << k << " of " << r.rows[k] << " rows";
    EXPECT_LE(r.rows.size(), std::size_t(16)) << "a band of at least H / 16 rows";
    // The planner uses the budget: the bands are not all the smallest (H / 16) once learned.
    if (full > 40) {
      EXPECT_LT(r.rows.size(), std::size_t(16)) << "bands sized to the budget, not fixed";
    }
  }
}

TEST(RefineBands, RowsWithMoreHitsGetSmallerBands) {
  // The object in the lower half: the bands there hold fewer rows than the empty top's.
  const Scene s{800, 800, 400, 800, 1.0};
  const Bands r = refine(s, learned_budget(33, 1), 1, 3e-4);
  int top = 0, bottom = s.H;  // the largest band starting in the empty top, the smallest in the object
  for (std::size_t k = 1; k < r.rows.size(); ++k) {
    if (r.y0[k] < 400) top = std::max(top, r.rows[k]);
    if (r.y0[k] >= 400 && r.y0[k] + r.rows[k] < s.H) bottom = std::min(bottom, r.rows[k]);
  }
  EXPECT_GT(top, bottom) << "empty rows weigh 0.2 of a hit row";
}

TEST(RefineBands, RefusesALowPictureOfTheWrongSize) {
  const FrameBudget fb;
  EXPECT_THROW(RefineBands(std::vector<float>(10), 4, 3, 100, fb), std::invalid_argument);
  EXPECT_THROW(RefineBands(std::vector<float>(12), 4, 3, 0, fb), std::invalid_argument);
  RefineBands one(std::vector<float>(12, -1.0f), 4, 3, 1, fb);
  EXPECT_EQ(one.next_rows(), 1);
  one.drawn(1.0);
  EXPECT_TRUE(one.done());
  EXPECT_EQ(one.next_rows(), 0);
}

}  // namespace
