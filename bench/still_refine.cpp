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
  // A band costs a fixed part (submission, the clears; at first the moving frames' fixed part)
  // and a part per unit of row weight, learned from the bands.
  double fixed = budget.fixed_cost_ms();  // then at most the cheapest band's
  double rate = 0;
  bool learned = false;
  bool equal = true;  // every band's rows the truth's
  const int least = std::max(1, H / 16);  // at most 16 frames, whatever the estimates
  for (int y = 0; y < H;) {
    const double room = o.target * o.budget_ms - fixed;
    int n = 1;
    double w = weight[std::size_t(y)];
    // Until a band has measured the rate, bands of `least` rows (the frames drawn whole's rate,
    // extrapolated from the moving frames' scales, can be several times low).
    while (y + n < H && (n < least || (learned && (w + weight[std::size_t(y + n)]) * rate <= room)))
      w += weight[std::size_t(y + n++)];
    const auto t0 = Clock::now();
    const engine::RaycastImage band = caster.render_rows(view, style, W, H, y, y + n);
    std::copy(band.rgba.begin(), band.rgba.end(), shown.begin() + std::ptrdiff_t(y) * W);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    equal = equal && std::equal(band.rgba.begin(), band.rgba.end(), truth.rgba.begin() + std::ptrdiff_t(y) * W) &&
            std::equal(band.depth.begin(), band.depth.end(), truth.depth.begin() + std::ptrdiff_t(y) * W);
    r.ms.push_back(ms);
    r.rows.push_back(n);
    // As engine::FrameBudget learns: a rise at once, a fall at half weight; a band no dearer
    // than the fixed part says nothing of the rate.
    fixed = std::min(fixed, ms);
    const double now = (ms - fixed) / w;
    if (now > 0) rate = !learned || now > rate ? now : rate + 0.5 * (now - rate), learned = true;
    y += n;
  }
  const engine::RaycastImage after = caster.render(view, style, W, H);  // reuses the bands' picture
  r.equal = equal && after.reused && after.rgba == truth.rgba && after.depth == truth.depth && shown == truth.rgba;
  return r;
}

}  // namespace isotouch::bench
