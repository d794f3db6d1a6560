// The still view's band planner (engine/refine_bands.h), judged with injected band costs from
// a cost model the test defines (a fixed part per band plus a part per hit pixel and per miss
// at full resolution), no wall clock.
#include "isotouch/engine/refine_bands.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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
  /// A band's cost [ms]: fixed + per pixel (a miss costs `miss` of a hit; the planner starts
  /// from 0.2).
  double band_ms(int y0, int n, double fixed, double per_hit, double miss = 0.2) const {
    double c = fixed;
    for (int y = y0; y < y0 + n; ++y)
      for (int x = 0; x < W; ++x) c += per_hit * (hit(x, y) ? 1.0 : miss);
    return c;
  }
};

/// The bands' rows and costs until done (at most 10 * H bands).
struct Bands {
  std::vector<int> y0, rows;
  std::vector<double> ms;
  double hit_row_ms = 0, miss_row_ms = 0;  // the planner's fit at the end
};
Bands refine(const Scene& s, const FrameBudget& fb, double fixed, double per_hit, double miss = 0.2, int lscale = 2) {
  RefineBands bands(s.low(s.W / lscale, s.H / lscale), s.W / lscale, s.H / lscale, s.H, fb);
  Bands r;
  while (!bands.done() && int(r.rows.size()) < 10 * s.H) {
    const int y = bands.next_row(), n = bands.next_rows();
    const double ms = s.band_ms(y, n, fixed, per_hit, miss);
    r.y0.push_back(y);
    r.rows.push_back(n);
    r.ms.push_back(ms);
    bands.drawn(ms);
  }
  r.hit_row_ms = bands.hit_row_ms();
  r.miss_row_ms = bands.miss_row_ms();
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

/// A budget whose moving frames measured a fixed part of `fixed_ms` and a frame drawn whole
/// at scale 1 of `full_ms` (less the fixed part).
FrameBudget budget_with(double budget_ms, double fixed_ms, double full_ms) {
  FrameBudget fb(FrameBudgetOptions{budget_ms});
  fb.measured_whole(1.0, fixed_ms + full_ms, fixed_ms);
  return fb;
}

TEST(RefineBands, EveryBandFitsTheBudget) {
  // Full frames of 30-150 ms: each is spread over frames of at most the 33 ms budget.
  for (const double per_hit : {1e-4, 2e-4, 5e-4}) {
    const Scene s{640, 480, 60, 420, 0.8};
    const double full = s.band_ms(0, s.H, 0, per_hit);
    const Bands r = refine(s, learned_budget(33, 2), 2, per_hit);
    SCOPED_TRACE("full frame " + std::to_string(full) + " ms");
    for (std::size_t k = 0; k < r.ms.size(); ++k) EXPECT_LE(r.ms[k], 33.0) << "band " << k << " of " << r.rows[k] << " rows";
    // The planner uses the budget: the bands are not all one row.
    EXPECT_LT(r.rows.size(), std::size_t(s.H / 4)) << "bands sized to the budget";
  }
}

TEST(RefineBands, EveryBandFitsTheBudgetWhenTheEstimatesAreWrong) {
  // 1920 x 1440 from a 0.25-scale moving frame, a full frame of 3-30 budgets, a hit 20 times
  // a miss, 5 times, or as dear (the planner starts from 5), the whole frame's estimate 4
  // times low, right, or 2 times high, the object in the middle rows or over the whole
  // picture (zoomed in): every band, the first included, within the 33 ms budget; the bands
  // still use it (at most twice the frames a perfect split into the target share would take,
  // plus the slow start's doublings); the fitted costs of a row of hits and of misses are the
  // cost model's.
  for (const Scene& s : {Scene{1920, 1440, 300, 1300, 0.6}, Scene{1920, 1440, 0, 1440, 1.0}}) {
    for (const double full_ms : {100.0, 330.0, 1000.0}) {
      for (const double miss : {0.05, 0.2, 1.0}) {
        for (const double wrong : {0.25, 1.0, 2.0}) {
          const double per_hit = full_ms / s.band_ms(0, s.H, 0, 1.0, miss);
          const Bands r = refine(s, budget_with(33, 2, wrong * full_ms), 2, per_hit, miss, 4);
          SCOPED_TRACE("object rows " + std::to_string(s.obj0) + "-" + std::to_string(s.obj1) + ", full " +
                       std::to_string(full_ms) + " ms, miss " + std::to_string(miss) + ", estimate x" + std::to_string(wrong));
          for (std::size_t k = 0; k < r.ms.size(); ++k)
            EXPECT_LE(r.ms[k], 33.0) << "band " << k << " at row " << r.y0[k] << " of " << r.rows[k] << " rows";
          const double frames = full_ms / (0.9 * 33 - 2);
          EXPECT_LE(double(r.rows.size()), 2 * std::ceil(frames) + 2 * std::log2(double(s.H))) << "bands sized to the budget";
          const double hit_row = per_hit * s.cover * s.W + per_hit * miss * (1 - s.cover) * s.W;  // a row through the object
          EXPECT_NEAR(r.hit_row_ms * s.cover + r.miss_row_ms * (1 - s.cover), hit_row, 0.01 * hit_row);
          if (s.obj0 > 0) EXPECT_NEAR(r.miss_row_ms, per_hit * miss * s.W, 0.01 * per_hit * miss * s.W);
        }
      }
    }
  }
}

TEST(RefineBands, ALoadSpikeMakesTheNextBandsSmaller) {
  // A band that cost more than its fit (the machine was busy) leaves that much room.
  const Scene s{800, 800, 0, 800, 1.0};
  const FrameBudget fb = budget_with(33, 1, 200);
  RefineBands calm(s.low(400, 400), 400, 400, s.H, fb), spiked(s.low(400, 400), 400, 400, s.H, fb);
  // 0.24 ms a row: the slow start's 1, 2, 4 ... rows, then bands the budget holds.
  for (int k = 0; k < 9; ++k) {
    const double ms = s.band_ms(calm.next_row(), calm.next_rows(), 1, 3e-4);
    ASSERT_EQ(calm.next_rows(), spiked.next_rows());
    calm.drawn(ms);
    spiked.drawn(k == 8 ? ms + 10 : ms);
  }
  EXPECT_GT(calm.next_ms(), 0.8 * 33) << "the calm bands are sized by the budget";
  // The band after the spike leaves the spike's 10 ms: its calm cost + 10 within the target.
  EXPECT_LT(spiked.next_rows(), calm.next_rows());
  EXPECT_LE(s.band_ms(spiked.next_row(), spiked.next_rows(), 1, 3e-4) + 10, 0.9 * 33);
}

/// A window's band frames: each band's render costs `band_fixed` + `row_ms` a row (hit or
/// miss alike), and the frame around it (the slices, the panels, the present) `overhead` more.
/// The planner is told both, as the app measures them. The bands' rows and frame times.
struct WindowFrames {
  std::vector<int> rows;
  std::vector<double> frame_ms;
};
WindowFrames refine_in_window(RefineBands& bands, int H, double band_fixed, double row_ms, double overhead,
                              int stall_at = -1, double stall_ms = 0, bool stall_in_band = false) {
  WindowFrames r;
  while (!bands.done() && int(r.rows.size()) < 10 * H) {
    const int n = bands.next_rows();
    double band = band_fixed + row_ms * n, frame = band + overhead;
    if (int(r.rows.size()) == stall_at) {  // a stall: the machine suspended, the window minimised
      frame += stall_ms;
      if (stall_in_band) band += stall_ms;
    }
    r.rows.push_back(n);
    r.frame_ms.push_back(frame);
    bands.drawn(band, frame);
  }
  return r;
}

TEST(RefineBands, AFrameOverheadOutsideTheBandIsNotCountedPerRow) {
  // A 1440-row view whose frames cost 20 ms besides the band's rows (0.01 ms a row; 25 and 28
  // ms: bands the budget holds before the picture's end), against a 33 ms budget: a band of
  // R = floor((0.9 x 33 - overhead) / 0.01) rows fits the target share, so the refinement takes
  // the slow start's doublings up to R (1, 2, 4 ... rows) and ceil(1440 / R) bands after them
  // at most; each frame within the budget. Whether the band's render has a fixed part of its
  // own or not (the budget's moving frames measured one of 1 ms).
  const int H = 1440;
  const double budget = 33, row_ms = 0.01;
  for (const double overhead : {20.0, 25.0, 28.0})
  for (const double band_fixed : {0.0, 1.0}) {
    const Scene s{1920, H, 0, H, 0.6};  // every row alike: the slow start doubles both hits and misses
    RefineBands bands(s.low(480, 360), 480, 360, H, learned_budget(budget, 1));
    const WindowFrames r = refine_in_window(bands, H, band_fixed, row_ms, overhead - band_fixed);
    SCOPED_TRACE("frame overhead " + std::to_string(overhead) + " ms, the band's own fixed part " +
                 std::to_string(band_fixed) + " ms");
    const double R = std::floor((0.9 * budget - overhead) / row_ms);
    const double most = 1 + std::ceil(std::log2(R)) + std::ceil(H / R);
    std::string rows;
    for (int n : r.rows) rows += " " + std::to_string(n);
    EXPECT_LE(double(r.rows.size()), most) << "bands' rows:" << rows;
    for (std::size_t k = 0; k < r.frame_ms.size(); ++k) EXPECT_LE(r.frame_ms[k], budget) << "band " << k;
  }
}

TEST(RefineBands, AFrameOverTheBudgetWithoutItsBandStillGetsBandsOfTheMargin) {
  // Frames that cost 35 and 45 ms besides the band (the slices and panels of a large window:
  // over the 33 ms budget whatever the band) and 0.01 ms a row: no band can keep the budget,
  // so each band's rows get the budget's margin, 0.1 x 33 = 3.3 ms (R = 330 rows), on top of
  // the rest: the slow start's doublings up to R and ceil(1440 / R) bands after them at most
  // (one row a frame would take 1440 frames), each frame within the rest + the margin, give or
  // take the fit's error on the rows (5 % of the margin: its first bands take the moving
  // frames' 1 ms fixed part for the band's).
  const int H = 1440;
  const double budget = 33, row_ms = 0.01;
  for (const double overhead : {35.0, 45.0})
    for (const double band_fixed : {0.0, 1.0}) {
      const Scene s{1920, H, 0, H, 0.6};
      RefineBands bands(s.low(480, 360), 480, 360, H, learned_budget(budget, 1));
      const WindowFrames r = refine_in_window(bands, H, band_fixed, row_ms, overhead - band_fixed);
      SCOPED_TRACE("frame overhead " + std::to_string(overhead) + " ms, the band's own fixed part " +
                   std::to_string(band_fixed) + " ms");
      const double R = std::floor(0.1 * budget / row_ms);
      std::string rows;
      for (int n : r.rows) rows += " " + std::to_string(n);
      EXPECT_LE(double(r.rows.size()), 1 + std::ceil(std::log2(R)) + std::ceil(H / R)) << "bands' rows:" << rows;
      for (std::size_t k = 0; k < r.frame_ms.size(); ++k)
        EXPECT_LE(r.frame_ms[k], overhead + 1.05 * 0.1 * budget) << "band " << k;
    }
}

TEST(RefineBands, AStallIsNotACost) {
  // One frame of 2 s more (the window was minimised, the machine suspended; in the frame or in
  // the band's render) among frames of 25 ms besides the band and 0.011 ms a row: the rows cost
  // what they did, so the bands after it are the calm refinement's (a row either way: the fits
  // differ in rounding); after a stall in the slow start (the stalled band not measured, not
  // grown from) one band more at most. Every other frame within the budget.
  const int H = 2880;
  const double budget = 33, row_ms = 0.011, band_fixed = 1, overhead = 25;
  const Scene s{1920, H, 0, H, 0.6};
  RefineBands calm_bands(s.low(480, 360), 480, 360, H, learned_budget(budget, 1));
  const WindowFrames calm = refine_in_window(calm_bands, H, band_fixed, row_ms, overhead - band_fixed);
  ASSERT_GT(calm.rows.size(), 13u);
  const int budget_bound = 9;  // 1 2 4 ... 256 rows, then bands of floor((0.9 x 33 - 25) / 0.011) = 427
  ASSERT_LT(calm.rows[budget_bound], 2 * calm.rows[budget_bound - 1]) << "the budget holds band 9, not the slow start";
  for (const bool in_band : {false, true}) {
    for (const int k : {2, 5, budget_bound, 12}) {
      RefineBands bands(s.low(480, 360), 480, 360, H, learned_budget(budget, 1));
      const WindowFrames r = refine_in_window(bands, H, band_fixed, row_ms, overhead - band_fixed, k, 2000, in_band);
      SCOPED_TRACE(std::string("a 2 s stall in ") + (in_band ? "the band's render" : "the frame") + " of band " +
                   std::to_string(k));
      std::string rows;
      for (std::size_t j = 0; j < std::min<std::size_t>(r.rows.size(), 40); ++j) rows += " " + std::to_string(r.rows[j]);
      // As AFrameOverheadOutsideTheBandIsNotCountedPerRow: the slow start's doublings up to R
      // rows, then ceil(H / R) bands (one more after a stall in the slow start).
      const double R = std::floor((0.9 * budget - overhead) / row_ms);
      EXPECT_LE(double(r.rows.size()), 1 + std::ceil(std::log2(R)) + std::ceil(H / R) + (k < budget_bound))
          << "bands' rows:" << rows;
      if (k >= budget_bound) {
        ASSERT_EQ(r.rows.size(), calm.rows.size()) << "bands' rows:" << rows;
        for (std::size_t j = std::size_t(k) + 1; j + 1 < r.rows.size(); ++j)
          EXPECT_NEAR(r.rows[j], calm.rows[j], 1) << "band " << j << "; bands' rows:" << rows;
      } else {
        EXPECT_LE(r.rows.size(), calm.rows.size() + 1) << "bands' rows:" << rows;
      }
      for (std::size_t j = 0; j < r.frame_ms.size(); ++j)
        if (int(j) != k) EXPECT_LE(r.frame_ms[j], budget) << "band " << j;
    }
  }
}

TEST(RefineBands, ALoadSpikesRoomHalvesEachBand) {
  // A band 4 ms dearer than its rows (the machine was busy; in its render or in the rest of its
  // frame) among frames of 25 ms besides the band and 0.011 ms a row: the next band leaves the
  // 4 ms, the one after it 2, then 1 ...: band j after the spike costs at most the target share
  // less 4 / 2^(j-1) ms, and at least that less one row (bands hold whole rows), the last
  // band excepted. In the band's render the spike also enters the least-squares fit of a row's
  // cost (every row alike here: one cost a row, fitted to the bands' times less their fixed
  // 1 ms): a row costs row_ms + spike n_k / sum(n_i^2) over the bands drawn, which the band
  // leaves as well.
  const int H = 2880;
  const double budget = 33, row_ms = 0.011, band_fixed = 1, overhead = 25, spike = 4;
  const Scene s{1920, H, 0, H, 0.6};
  const int k = 9;  // a band the budget holds (AStallIsNotACost)
  for (const bool in_band : {false, true}) {
    RefineBands bands(s.low(480, 360), 480, 360, H, learned_budget(budget, 1));
    const WindowFrames r = refine_in_window(bands, H, band_fixed, row_ms, overhead - band_fixed, k, spike, in_band);
    SCOPED_TRACE(std::string("a 4 ms spike in ") + (in_band ? "the band's render" : "the frame"));
    ASSERT_GT(r.rows.size(), std::size_t(k + 4));
    double sum_n2 = 0;  // over the bands drawn before band k + j
    for (std::size_t j = 0; j <= std::size_t(k); ++j) sum_n2 += double(r.rows[j]) * r.rows[j];
    for (std::size_t j = 1; k + j + 1 < r.rows.size(); ++j) {
      const double n = r.rows[k + j], fitted_row = row_ms + (in_band ? spike * r.rows[k] / sum_n2 : 0.0);
      const double frame = r.frame_ms[k + j], room = spike / std::pow(2.0, double(j) - 1) + (fitted_row - row_ms) * n;
      EXPECT_LE(frame + room, 0.9 * budget + 1e-9) << "band " << j << " after the spike leaves its room";
      EXPECT_GE(frame + room + fitted_row, 0.9 * budget - 1e-9) << "band " << j << " after the spike: " << n << " rows";
      sum_n2 += n * n;
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
