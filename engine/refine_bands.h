// refine_bands.h - a still view refined to full resolution one band of rows per frame.
//
// After moving frames drawn at a lower resolution (FrameBudget), a view that stops is drawn
// whole at full resolution over the next frames, a band of rows each (RayCaster::render_rows),
// each band sized so that its frame keeps the budget: VTK's and 3D Slicer's "still update
// rate", spread over frames instead of one long frame. The bands go from row 0 down; a band
// costs a fixed part (submission, the clears) and a part per unit of row weight, where a row
// weighs by its hits in the last moving frame (a hit is marched to the surface and shaded:
// 1; a miss 0.2). Until a band has measured the rate, bands hold `least` rows (H / 16: at most
// 16 frames whatever the estimates; the whole frames' rate extrapolated from the moving
// frames' scales can be several times low); then as many rows (at least `least`) as the
// budget's target share holds. No wall clock inside: the caller measures each band.
#pragma once
#include <vector>

#include "isotouch/engine/frame_budget.h"

namespace isotouch::engine {

class RefineBands {
 public:
  /// @param low_depth the last moving frame's depth, lw x lh row-major (< 0: no hit)
  /// @param H the full picture's rows (> 0)
  /// @param budget its fixed part starts the band's (then at most the cheapest band's)
  /// @throws std::invalid_argument if H <= 0, lw or lh <= 0 or low_depth.size() != lw * lh.
  RefineBands(const std::vector<float>& low_depth, int lw, int lh, int H, const FrameBudget& budget);

  /// All rows drawn.
  bool done() const { return next_ >= H_; }
  /// The first row of the next band.
  int next_row() const { return next_; }
  /// The rows the next band holds (>= 1; 0 when done()).
  int next_rows() const;
  /// The next band (next_row(), next_rows()) was drawn in `ms` [ms] (including what the
  /// caller does with its rows); moves on to the rows after it.
  void drawn(double ms);

 private:
  std::vector<double> weight_;  // each full-resolution row's cost share
  int H_ = 0, least_ = 1, next_ = 0;
  double budget_ms_ = 0, target_ = 0.9;
  double fixed_ = 0, rate_ = 0;  // [ms] per band; [ms] per unit of row weight
  bool learned_ = false;
};

}  // namespace isotouch::engine
