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
  const double room = o_.target * o_.budget_ms - fixed_ms_;
  if (room <= 0) return o_.min_scale;
  const double s = std::sqrt(room / full_ms_);
  return std::clamp(std::floor(s * 32) / 32, o_.min_scale, 1.0);
}

/// A rise is taken at once (a frame over the budget is what the user feels); a fall at half
/// weight, so that one cheap frame does not make the next one large.
void FrameBudget::measured_whole(double scale, double ms, double fixed_ms) {
  if (!(scale > 0) || !std::isfinite(scale) || !(ms > 0) || !std::isfinite(ms)) return;
  const double fixed = std::isfinite(fixed_ms) ? std::clamp(fixed_ms, 0.0, ms) : 0.0;
  const double full = (ms - fixed) / (scale * scale);
  const auto follow = [first = samples_ == 0](double& est, double v) {
    if (first || v > est) est = v;
    else est += 0.5 * (v - est);
  };
  follow(full_ms_, full);
  follow(fixed_ms_, fixed);
  ++samples_;
}

}  // namespace isotouch::engine
