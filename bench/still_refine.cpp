#include "isotouch/bench/still_refine.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

namespace isotouch::bench {

double StillRefinement::total_ms() const { return std::accumulate(ms.begin(), ms.end(), 0.0); }
double StillRefinement::max_ms() const { return ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end()); }

namespace {

/// Each row's share of a frame's cost, from the last moving frame (`low`, rw x rh): its hit
/// pixels (marched to the surface and shaded) weigh 1, the others 0.2 (a miss is marched
/// through the box or not at all).
std::vector<double> row_weights(const engine::RaycastImage& low, int H) {
  std::vector<double> w(std::size_t(H), 0.0);
  for (int y = 0; y < H; ++y) {
    const int ly = std::min(low.height - 1, y * low.height / H);
    int hits = 0;
    for (int x = 0; x < low.width; ++x) hits += low.depth[std::size_t(ly) * std::size_t(low.width) + std::size_t(x)] >= 0;
    w[std::size_t(y)] = 0.2 + 0.8 * double(hits) / low.width;
  }
  return w;
}

}  // namespace

StillRefinement refine_still(engine::RayCaster& caster, const engine::CameraView& view,
                             const engine::RaycastStyle& style, int W, int H, int rw, int rh,
                             const engine::FrameBudget& budget, std::vector<std::uint32_t>& shown) {
  using Clock = std::chrono::steady_clock;
  StillRefinement r;
  const engine::RaycastImage truth = caster.render(view, style, W, H);
  const std::vector<double> weight = row_weights(caster.render(view, style, rw, rh), H);  // as the last moving frame left the buffers
  const engine::FrameBudgetOptions& o = budget.options();
  const double room = std::max(0.0, o.target * o.budget_ms - budget.fixed_cost_ms());
  // [ms per unit of weight]: at first from the frames drawn whole, then from the bands drawn
  // (their fixed part included).
  double rate = budget.full_cost_ms() / std::max(1e-9, std::accumulate(weight.begin(), weight.end(), 0.0));
  double measured = 0;
  engine::RaycastImage band;
  for (int y = 0; y < H;) {
    const double planned = measured > 0 ? o.target * o.budget_ms : room;
    int n = 1;
    double w = weight[std::size_t(y)];
    while (y + n < H && (w + weight[std::size_t(y + n)]) * rate <= planned) w += weight[std::size_t(y + n++)];
    const auto t0 = Clock::now();
    band = caster.render_rows(view, style, W, H, y, y + n);
    std::copy_n(band.rgba.begin() + std::ptrdiff_t(y) * W, std::ptrdiff_t(n) * W, shown.begin() + std::ptrdiff_t(y) * W);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    r.ms.push_back(ms);
    r.rows.push_back(n);
    // As engine::FrameBudget learns: a rise at once, a fall at half weight.
    const double now = ms / w;
    rate = measured == 0 || now > rate ? now : rate + 0.5 * (now - rate);
    measured = now;
    y += n;
  }
  r.equal = band.rgba == truth.rgba && band.depth == truth.depth && shown == truth.rgba;
  return r;
}

}  // namespace isotouch::bench
