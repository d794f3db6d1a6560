// refine_bands.h - a still view refined to full resolution one band of rows per frame.
//
// After moving frames drawn at a lower resolution (FrameBudget), a view that stops is drawn
// whole at full resolution over the next frames, a band of rows each (RayCaster::render_rows),
// each band sized so that its frame keeps the budget: VTK's and 3D Slicer's "still update
// rate", spread over frames instead of one long frame. The bands go from row 0 down.
//
// A band's frame costs the rest of the frame (what the frame does besides the band: in the
// window the slices, the panels, the present; measured as the frame less the band, a rise
// taken at once, a fall at half weight), the band's fixed part (submission, the clears; the
// budget's fixed part, then at most the cheapest band's) and a part per full-resolution row
// (the band's own time less its fixed part: the rest of the frame is never fitted per row,
// where a frame's 20 ms outside its band made every band one row), a row's cost split by the
// last moving frame's hits along it: a full row of hits costs a (marched to the surface and
// shaded), a full row of misses b. a and b are measured, not extrapolated from the moving
// frames (their estimate of a whole frame was about 4 times low on the head at 1920x1440):
// fitted (least squares, non-negative) to the bands drawn so far, each band's cost less the
// fixed part; while the bands have held no hits (no misses), a is 5 b (b is a / 5). The first
// band is one row; then a band holds the most rows whose predicted cost, plus what the drawn
// bands cost over the predictions they were sized on (a load spike is kept as room, halved
// each band after it), stays within the budget's target share, and (slow start) at most
// twice the hit rows and twice the miss rows of the largest band drawn, at least one of each.
// Where the rest of the frame alone leaves no room for a row, a band's rows get the budget's
// margin ((1 - target) of it) on top of the rest, not one row a frame. No floor on rows: a
// full frame of many budgets takes as many frames. A band's frame over 4 budgets (a stall:
// the window minimised, the machine suspended) is not a cost: not fitted, not kept as room,
// not grown from; its rows are drawn.
// No wall clock inside: the caller measures each band.
#pragma once
#include <vector>

#include "isotouch/engine/frame_budget.h"

namespace isotouch::engine {

class RefineBands {
 public:
  /// @param low_depth the last moving frame's depth, lw x lh row-major (< 0: no hit)
  /// @param H the full picture's rows (> 0)
  /// @param budget its budget and target share; its fixed part starts the band's
  /// @throws std::invalid_argument if H <= 0, lw or lh <= 0 or low_depth.size() != lw * lh.
  RefineBands(const std::vector<float>& low_depth, int lw, int lh, int H, const FrameBudget& budget);

  /// All rows drawn.
  bool done() const { return next_ >= H_; }
  /// The first row of the next band.
  int next_row() const { return next_; }
  /// The rows the next band holds (>= 1; 0 when done()).
  int next_rows() const;
  /// The predicted cost of the next band [ms] (fixed part included; 0 when done()).
  double next_ms() const;
  /// The next band (next_row(), next_rows()) was drawn in `band_ms` [ms] (its render and what
  /// the caller does with its rows) in a frame of `frame_ms` [ms] all told (the band, the rest
  /// of the frame, the present); moves on to the rows after it. The band's time is fitted per
  /// row; the rest of the frame (frame_ms - band_ms) is a part of every band's frame.
  void drawn(double band_ms, double frame_ms);
  /// A band that was its frame's whole cost (nothing else in the frame).
  void drawn(double ms) { drawn(ms, ms); }

  /// The fitted cost of a full row of hits and of misses [ms].
  double hit_row_ms() const { return a_; }
  double miss_row_ms() const { return b_; }

 private:
  struct Drawn {
    double hits, misses, ms;
  };
  void fit();
  double band_cost(double hits, double misses) const;  // predicted, fixed part and margin included
  std::vector<double> hit_;  // each full-resolution row's share of hits (0..1)
  std::vector<Drawn> drawn_;
  int H_ = 0, next_ = 0;
  double budget_ms_ = 0, target_ = 0.9;
  double fixed_ = 0;                    // [ms] per band, of its render
  double rest_ = 0;                     // [ms] per band frame, outside its render (slices, panels, present)
  double a_ = 0, b_ = 0;                // [ms] per full row of hits, of misses
  double over_ = 0;                     // what a drawn band cost over its prediction, halved each band [ms]
  double most_hits_ = 0, most_misses_ = 0;  // the largest drawn band's hit and miss rows
};

}  // namespace isotouch::engine
