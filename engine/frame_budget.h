// frame_budget.h - the ray caster's resolution chosen per frame to keep a frame-time budget.
//
// Interactive volume renderers (VTK's and 3D Slicer's interactive vs still update rates,
// ParaView's LOD) draw at reduced resolution while the view moves and refine when it stops.
// FrameBudget is that choice as a controller, not a switch. A frame drawn whole costs a part
// that scales with its pixels (the ray caster's passes: scale^2) and a part that does not
// (submission, the upscale to the window, overlays); from each frame's measured cost and
// fixed part it keeps estimates of both and gives, while the view moves, the largest scale
// whose predicted cost fits the budget's target (a 0.9 share of the budget), on a grid of
// 1/32 so that small cost noise does not change the picture's size every frame. A fixed part
// above the target leaves the smallest scale (the cheapest frame there is).
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

  /// A frame drawn whole at `scale` cost `ms` [ms], of which `fixed_ms` does not scale with
  /// its pixels (clamped to [0, ms]); ignored when not finite or not positive.
  void measured_whole(double scale, double ms, double fixed_ms = 0);

  /// The estimate of the scaling part of a frame drawn whole at scale 1 [ms]; 0 before any
  /// measurement.
  double full_cost_ms() const { return full_ms_; }
  /// The estimate of a frame's fixed part [ms].
  double fixed_cost_ms() const { return fixed_ms_; }
  const FrameBudgetOptions& options() const { return o_; }

 private:
  FrameBudgetOptions o_;
  double full_ms_ = 0;   // smoothed estimate of the scaling part at scale 1 [ms]
  double fixed_ms_ = 0;  // smoothed estimate of the fixed part [ms]
  int samples_ = 0;
};

}  // namespace isotouch::engine
