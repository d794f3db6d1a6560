// frame_budget.h - the ray caster's resolution chosen per frame to keep a frame-time budget.
//
// Interactive volume renderers (VTK's and 3D Slicer's interactive vs still update rates,
// ParaView's LOD) draw at reduced resolution while the view moves and refine when it stops.
// FrameBudget is that choice as a controller, not a switch: it keeps an estimate of what a
// frame drawn whole costs at full resolution, from the measured cost of each frame at the
// scale it was drawn (cost ~ pixels ~ scale^2), and gives
// - while the view moves: the largest scale whose predicted cost fits the budget's target
//   (a 0.9 share of the budget), on a grid of 1/32 so small cost noise does not change the
//   picture's size every frame;
// - when the view is still: how many full-resolution refinement steps (of `steps` equal parts
//   of the picture, e.g. interleaved pixel sets) the next frame can draw within the target,
//   at least one, until the picture is whole.
// No wall clock inside: the caller measures and reports costs (deterministic tests).
#pragma once

namespace isotouch::engine {

struct FrameBudgetOptions {
  double budget_ms = 33;    ///< a frame's budget [ms]; <= 0: no budget (always scale 1)
  double min_scale = 0.25;  ///< the smallest fraction of the window's resolution drawn
  double target = 0.9;      ///< the share of the budget a frame is planned to take
};

class FrameBudget {
 public:
  explicit FrameBudget(FrameBudgetOptions o = {});

  /// The scale (fraction of the window's resolution per axis, in [min_scale, 1]) to draw the
  /// next moving frame at. Before any cost is known: 1 (the first frame measures).
  double moving_scale() const;

  /// How many of `steps` equal full-resolution parts the next still frame should draw (at
  /// least 1, at most `steps_left`).
  int refine_steps(int steps, int steps_left) const;

  /// A frame drawn whole at `scale` cost `ms` (the ray caster's time, not the upscale or the
  /// overlays); ignored when not finite or not positive.
  void measured_whole(double scale, double ms);
  /// A still frame drew `parts` of `steps` full-resolution parts in `ms`.
  void measured_parts(int parts, int steps, double ms);

  /// The estimate of a frame drawn whole at scale 1 [ms]; 0 before any measurement.
  double full_cost_ms() const { return full_ms_; }
  const FrameBudgetOptions& options() const { return o_; }

 private:
  void learn(double full_ms);
  FrameBudgetOptions o_;
  double full_ms_ = 0;  // smoothed estimate of a whole frame at scale 1 [ms]
  int samples_ = 0;
};

}  // namespace isotouch::engine
