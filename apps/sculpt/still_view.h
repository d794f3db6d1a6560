// still_view.h - the window's view refined to full resolution over frames when it stops.
//
// While the camera or the window moves, the frame budget draws the picture at a lower scale
// (engine/frame_budget.h). When the view stops, drawing it whole at full resolution in one
// frame would take that frame past the budget (60 ms on the chest at 1024x768 here); instead
// the full picture is drawn a band of rows per frame (RayCaster::render_rows, bands planned by
// engine::RefineBands), each band put over the last moving frame's picture scaled up, and the
// frame after the last band is an ordinary render() that reuses the bands' picture and draws
// the probe's glyphs over it. Each band is sized by the bands' own times (per row) and the
// rest of their frames (the slices, the panels, the present: a part of every band's frame).
// While bands are drawn the glyphs show only in the rows not yet refined (render_rows draws
// no primitives); an edit, a camera move or a resize ends the refinement (the edited picture
// is drawn at once, as without a budget).
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "isotouch/engine/frame_budget.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/engine/refine_bands.h"

namespace isotouch::sculpt {

class StillView {
 public:
  /// Starts refining to rw x rh from the last moving frame `low` (its rgba and depth on the
  /// host, smaller than rw x rh). False (nothing started) when `low` is not such a frame.
  bool start(const engine::RaycastImage& low, int rw, int rh, const engine::FrameBudget& budget);
  bool active() const { return bands_.has_value(); }
  void stop() { bands_.reset(); }
  /// Draws the next band at rw x rh (the caster's in-place output off: the band's rows come
  /// back to the host) and leaves the picture so far at the window's size fb in `px` (RGBA).
  /// The band's frame then reports its time to frame_drawn().
  /// @return the band's rows.
  int band(engine::RayCaster& caster, const engine::CameraView& view, const engine::RaycastStyle& style,
           const std::array<int, 2>& fb, std::vector<std::uint32_t>& px);
  /// The band drawn last holds the picture's last rows (after band(), before frame_drawn()).
  bool last_band() const { return bands_ && bands_->next_row() + bands_->next_rows() >= rh_; }
  /// The band took `band_ms` [ms] (band()) and the frame that showed it `frame_ms`, all of it
  /// (the band, the rest of the frame, the present): the next band is sized on what its rows
  /// cost and what the rest of a frame costs. After the last band active() is false: the next
  /// render() of the view reuses the bands.
  void frame_drawn(double band_ms, double frame_ms);

 private:
  std::optional<engine::RefineBands> bands_;
  std::vector<std::uint32_t> still_;  // rw x rh: the low picture scaled up, the bands over it
  int rw_ = 0, rh_ = 0;
};

}  // namespace isotouch::sculpt
