#include "isotouch/apps/sculpt/still_view.h"

#include <algorithm>

#include "isotouch/engine/upscale.h"

namespace isotouch::sculpt {

bool StillView::start(const engine::RaycastImage& low, int rw, int rh, const engine::FrameBudget& budget) {
  bands_.reset();
  const std::size_t n = std::size_t(low.width) * std::size_t(low.height);
  if (low.width <= 0 || low.height <= 0 || low.width >= rw || low.height >= rh || low.rgba.size() != n ||
      low.depth.size() != n)
    return false;
  rw_ = rw;
  rh_ = rh;
  still_.resize(std::size_t(rw) * std::size_t(rh));
  engine::upscale_bilinear(low.rgba.data(), low.width, low.height, still_.data(), rw, rh);
  bands_.emplace(low.depth, low.width, low.height, rh, budget);
  return true;
}

int StillView::band(engine::RayCaster& caster, const engine::CameraView& view, const engine::RaycastStyle& style,
                    const std::array<int, 2>& fb, std::vector<std::uint32_t>& px) {
  if (!bands_) return 0;
  const int y = bands_->next_row(), n = bands_->next_rows();
  caster.set_in_place(false);
  const engine::RaycastImage rows = caster.render_rows(view, style, rw_, rh_, y, y + n);
  std::copy(rows.rgba.begin(), rows.rgba.end(), still_.begin() + std::ptrdiff_t(y) * rw_);
  if (fb[0] == rw_ && fb[1] == rh_) {
    px = still_;
  } else {
    px.resize(std::size_t(fb[0]) * std::size_t(fb[1]));
    engine::upscale_bilinear(still_.data(), rw_, rh_, px.data(), fb[0], fb[1]);
  }
  return n;
}

void StillView::frame_drawn(double band_ms, double frame_ms) {
  if (!bands_) return;
  bands_->drawn(band_ms, frame_ms);
  if (bands_->done()) bands_.reset();
}

}  // namespace isotouch::sculpt
