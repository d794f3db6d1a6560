#include "isotouch/engine/refine_bands.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace isotouch::engine {

RefineBands::RefineBands(const std::vector<float>& low_depth, int lw, int lh, int H, const FrameBudget& budget)
    : H_(H),
      least_(std::max(1, H / 16)),
      budget_ms_(budget.options().budget_ms),
      target_(budget.options().target),
      fixed_(budget.fixed_cost_ms()) {
  if (H <= 0 || lw <= 0 || lh <= 0 || low_depth.size() != std::size_t(lw) * std::size_t(lh))
    throw std::invalid_argument("refine bands: a " + std::to_string(H) + "-row picture from a " + std::to_string(lw) +
                                " x " + std::to_string(lh) + " frame with " + std::to_string(low_depth.size()) +
                                " depths");
  weight_.assign(std::size_t(H), 0.0);
  for (int y = 0; y < H; ++y) {
    const int ly = std::min(lh - 1, int(std::int64_t(y) * lh / H));
    int hits = 0;
    for (int x = 0; x < lw; ++x) hits += low_depth[std::size_t(ly) * std::size_t(lw) + std::size_t(x)] >= 0;
    weight_[std::size_t(y)] = 0.2 + 0.8 * double(hits) / lw;
  }
}

int RefineBands::next_rows() const {
  if (done()) return 0;
  const double room = target_ * budget_ms_ - fixed_;
  int n = 1;
  double w = weight_[std::size_t(next_)];
  while (next_ + n < H_ && (n < least_ || (learned_ && (w + weight_[std::size_t(next_ + n)]) * rate_ <= room)))
    w += weight_[std::size_t(next_ + n++)];
  return n;
}

/// As FrameBudget learns: a rise at once, a fall at half weight; a band no dearer than the
/// fixed part says nothing of the rate.
void RefineBands::drawn(double ms) {
  const int n = next_rows();
  if (n == 0) return;
  double w = 0;
  for (int y = next_; y < next_ + n; ++y) w += weight_[std::size_t(y)];
  next_ += n;
  if (!std::isfinite(ms) || ms < 0) return;
  fixed_ = std::min(fixed_, ms);
  const double now = (ms - fixed_) / w;
  if (now > 0) rate_ = !learned_ || now > rate_ ? now : rate_ + 0.5 * (now - rate_), learned_ = true;
}

}  // namespace isotouch::engine
