#include "isotouch/engine/frame_budget.h"

#include <algorithm>
#include <cmath>

namespace isotouch::engine {

FrameBudget::FrameBudget(FrameBudgetOptions o) : o_(o) {
  if (!std::isfinite(o_.budget_ms)) o_.budget_ms = 0;
  o_.min_scale = std::isfinite(o_.min_scale) ? std::clamp(o_.min_scale, 1.0 / 32, 1.0) : 0.25;
  o_.target = std::isfinite(o_.target) ? std::clamp(o_.target, 0.1, 1.0) : 0.9;
}

double FrameBudget::moving_scale() const {
  if (o_.budget_ms <= 0 || full_ms_ <= 0) return 1.0;
  const double s = std::sqrt(o_.target * o_.budget_ms / full_ms_);
  return std::clamp(std::floor(s * 32) / 32, o_.min_scale, 1.0);
}

int FrameBudget::refine_steps(int steps, int steps_left) const {
  if (steps_left <= 0) return 0;
  if (o_.budget_ms <= 0 || full_ms_ <= 0 || steps <= 0) return steps_left;
  const double part_ms = full_ms_ / steps;
  const int fit = int(std::floor(o_.target * o_.budget_ms / part_ms));
  return std::clamp(fit, 1, steps_left);
}

void FrameBudget::measured_whole(double scale, double ms) {
  if (!(scale > 0) || !std::isfinite(scale) || !(ms > 0) || !std::isfinite(ms)) return;
  learn(ms / (scale * scale));
}

void FrameBudget::measured_parts(int parts, int steps, double ms) {
  if (parts <= 0 || steps <= 0 || !(ms > 0) || !std::isfinite(ms)) return;
  learn(ms * steps / parts);
}

/// A rise is taken at once (a frame over the budget is what the user feels); a fall at half
/// weight, so one cheap frame does not make the next one large.
void FrameBudget::learn(double full_ms) {
  if (samples_++ == 0 || full_ms > full_ms_) full_ms_ = full_ms;
  else full_ms_ += 0.5 * (full_ms - full_ms_);
}

}  // namespace isotouch::engine
