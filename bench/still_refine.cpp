#include "isotouch/bench/still_refine.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include "isotouch/engine/refine_bands.h"

namespace isotouch::bench {

double StillRefinement::total_ms() const { return std::accumulate(ms.begin(), ms.end(), 0.0); }
double StillRefinement::max_ms() const { return ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end()); }

StillRefinement refine_still(engine::RayCaster& caster, const engine::CameraView& view,
                             const engine::RaycastStyle& style, int W, int H, int rw, int rh,
                             const engine::FrameBudget& budget, std::vector<std::uint32_t>& shown) {
  using Clock = std::chrono::steady_clock;
  StillRefinement r;
  const engine::RaycastImage truth = caster.render(view, style, W, H);
  const engine::RaycastImage low = caster.render(view, style, rw, rh);  // as the last moving frame left the buffers
  engine::RefineBands bands(low.depth, rw, rh, H, budget);
  bool equal = true;  // every band's rows the truth's
  while (!bands.done()) {
    const int y = bands.next_row(), n = bands.next_rows();
    const auto t0 = Clock::now();
    const engine::RaycastImage band = caster.render_rows(view, style, W, H, y, y + n);
    std::copy(band.rgba.begin(), band.rgba.end(), shown.begin() + std::ptrdiff_t(y) * W);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    equal = equal && std::equal(band.rgba.begin(), band.rgba.end(), truth.rgba.begin() + std::ptrdiff_t(y) * W) &&
            std::equal(band.depth.begin(), band.depth.end(), truth.depth.begin() + std::ptrdiff_t(y) * W);
    r.ms.push_back(ms);
    r.rows.push_back(n);
    bands.drawn(ms);
  }
  const engine::RaycastImage after = caster.render(view, style, W, H);  // reuses the bands' picture
  r.equal = equal && after.reused && after.rgba == truth.rgba && after.depth == truth.depth && shown == truth.rgba;
  return r;
}

}  // namespace isotouch::bench
