// tool_ticks.h - how `isotouch serve`'s command thread turns time and contact into the tool's
// applications and strokes while a client's `apply` holds (service/serve.cpp's feed_tool):
//   - a thread that fell behind (a save, a loaded machine) runs its next tick a period from
//     now, not a burst of the ticks it missed (next_tick), and applies the tool over the time
//     since its last application, at most two periods (tool_dt): what it could not apply while
//     it did not run is not carved at once;
//   - a stroke (one undo step) goes on through a contact lost for less than kStrokeGapS (a carve
//     breaking through under a still probe finds the material again a few ticks later: one
//     press, not several), and ends once the probe has been out of contact for kStrokeGapS of
//     tool time (the ticks' tool_dt: on a thread held up past two periods a tick counts two
//     periods, so the stroke may outlast kStrokeGapS of wall time).
// Pure functions of the clock values given: tests/test_tool_ticks.cpp. Part of isotouch::service.
#pragma once
#include <chrono>

namespace isotouch::service {

/// How long a stroke's probe may be out of contact and the stroke go on [s].
inline constexpr double kStrokeGapS = 0.1;

/// The command thread's next tick after one due at `due` that ran at `now`: `due + period`,
/// or `now + period` when the thread is more than a period behind (no burst of missed ticks).
std::chrono::steady_clock::time_point next_tick(std::chrono::steady_clock::time_point due,
                                                std::chrono::steady_clock::time_point now,
                                                std::chrono::steady_clock::duration period);

/// The time the tool is applied over at a tick `since_s` after its last application [s]:
/// clamped to [0, 2 period_s].
double tool_dt(double since_s, double period_s);

/// The open stroke's contact, tick by tick: whether it ends.
class StrokeGap {
 public:
  /// A tick `dt_s` long with the probe in contact: the stroke goes on.
  void in_contact() { apart_s_ = 0; }
  /// A tick `dt_s` long out of contact: true once the probe has been out of contact for
  /// kStrokeGapS in a row (the stroke ends; the count starts again).
  bool out_of_contact(double dt_s);
  /// The stroke ended for another reason (stop, undo, a new session): the count starts again.
  void reset() { apart_s_ = 0; }

 private:
  double apart_s_ = 0;
};

}  // namespace isotouch::service
