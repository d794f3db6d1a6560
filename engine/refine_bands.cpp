#include "isotouch/engine/refine_bands.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace isotouch::engine {

namespace {
constexpr double kHitPerMiss = 5;  // a hit row's cost over a miss row's until measured
constexpr double kStall = 4;       // a frame over this many budgets is a stall, not a cost
}

RefineBands::RefineBands(const std::vector<float>& low_depth, int lw, int lh, int H, const FrameBudget& budget)
    : H_(H), budget_ms_(budget.options().budget_ms), target_(budget.options().target), fixed_(budget.fixed_cost_ms()) {
  if (H <= 0 || lw <= 0 || lh <= 0 || low_depth.size() != std::size_t(lw) * std::size_t(lh))
    throw std::invalid_argument("refine bands: a " + std::to_string(H) + "-row picture from a " + std::to_string(lw) +
                                " x " + std::to_string(lh) + " frame with " + std::to_string(low_depth.size()) +
                                " depths");
  hit_.assign(std::size_t(H), 0.0);
  for (int y = 0; y < H; ++y) {
    const int ly = std::min(lh - 1, int(std::int64_t(y) * lh / H));
    int n = 0;
    for (int x = 0; x < lw; ++x) n += low_depth[std::size_t(ly) * std::size_t(lw) + std::size_t(x)] >= 0;
    hit_[std::size_t(y)] = double(n) / lw;
  }
}

double RefineBands::band_cost(double hits, double misses) const {
  return rest_ + fixed_ + a_ * hits + b_ * misses + over_;
}

int RefineBands::next_rows() const {
  if (done()) return 0;
  // The first band is one row: its cost measured, not extrapolated. Then slow start: at most
  // twice the largest drawn band's hit rows and miss rows (at least one row of each).
  if (drawn_.empty()) return 1;
  double room = target_ * budget_ms_;
  // Where the rest of the frame leaves no room for one row (every frame is over the target
  // whatever the band), a band gets the budget's margin, (1 - target) of it, on top of the
  // rest: the frames run over by what the rest costs, not by the band, and the picture still
  // ends in a bounded number of frames (not one row a frame).
  const double first = hit_[std::size_t(next_)];
  if (band_cost(first, 1 - first) > room) room = band_cost(0, 0) + (1 - target_) * budget_ms_;
  const double max_hits = std::max(1.0, 2 * most_hits_), max_misses = std::max(1.0, 2 * most_misses_);
  int n = 1;
  double h = hit_[std::size_t(next_)];
  while (next_ + n < H_) {
    const double h2 = h + hit_[std::size_t(next_ + n)], m2 = (n + 1) - h2;
    if (band_cost(h2, m2) > room || h2 > max_hits || m2 > max_misses) break;
    h = h2;
    ++n;
  }
  return n;
}

double RefineBands::next_ms() const {
  const int n = next_rows();
  double h = 0;
  for (int y = next_; y < next_ + n; ++y) h += hit_[std::size_t(y)];
  return n == 0 ? 0.0 : band_cost(h, n - h);
}

/// Non-negative least squares of (ms - fixed) = a hits + b misses over the bands drawn. A
/// coefficient the bands cannot tell (no hits drawn, or no misses) is 5:1 of the other, as is
/// a fit with a negative coefficient (then one coefficient fitted).
void RefineBands::fit() {
  double shh = 0, shm = 0, smm = 0, shy = 0, smy = 0;
  for (const Drawn& d : drawn_) {
    const double y = std::max(0.0, d.ms - fixed_);
    shh += d.hits * d.hits, shm += d.hits * d.misses, smm += d.misses * d.misses;
    shy += d.hits * y, smy += d.misses * y;
  }
  double a, b;
  const double det = shh * smm - shm * shm;
  if (shh <= 0) {  // misses only
    b = smy / smm;
    a = kHitPerMiss * b;
  } else if (smm <= 0) {  // hits only
    a = shy / shh;
    b = a / kHitPerMiss;
  } else {
    a = det > 1e-9 * shh * smm ? (shy * smm - smy * shm) / det : -1;
    b = det > 1e-9 * shh * smm ? (smy * shh - shy * shm) / det : -1;
    if (!(a >= 0 && b >= 0)) {
      const double sw = kHitPerMiss * kHitPerMiss * shh + 2 * kHitPerMiss * shm + smm;
      b = (kHitPerMiss * shy + smy) / sw;
      a = kHitPerMiss * b;
    }
  }
  a_ = std::isfinite(a) ? std::max(0.0, a) : a_;
  b_ = std::isfinite(b) ? std::max(0.0, b) : b_;
}

void RefineBands::drawn(double band_ms, double frame_ms) {
  const int n = next_rows();
  if (n == 0) return;
  double h = 0;
  for (int y = next_; y < next_ + n; ++y) h += hit_[std::size_t(y)];
  next_ += n;
  if (!std::isfinite(band_ms) || band_ms < 0 || !std::isfinite(frame_ms)) return;
  // A stall (the window minimised, the machine suspended: a frame of many budgets) says nothing
  // of what rows cost: not fitted, not kept as room, not grown from (slow start).
  if (budget_ms_ > 0 && std::max(band_ms, frame_ms) > kStall * budget_ms_) return;
  const double ms = band_ms, rest = std::max(0.0, frame_ms - band_ms);
  // The rest of the frame (slices, panels, present): a rise taken at once, a fall at half weight.
  rest_ = drawn_.empty() ? rest : rest > rest_ ? rest : rest_ + 0.5 * (rest - rest_);
  // What the band cost over the prediction it was sized on (the first: none) stays as room,
  // halved each band after it (a load spike passes).
  if (!drawn_.empty()) over_ = std::max(0.5 * over_, ms - (fixed_ + a_ * h + b_ * (n - h)));
  fixed_ = std::min(fixed_, ms);
  drawn_.push_back({h, n - h, ms});
  most_hits_ = std::max(most_hits_, h);
  most_misses_ = std::max(most_misses_, n - h);
  fit();
}

}  // namespace isotouch::engine
