#include "isotouch/bench/scale_quality.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iterator>
#include <limits>
#include <ostream>
#include <sstream>

#include "isotouch/engine/picture_error.h"

namespace isotouch::bench {

std::vector<ScaleQuality> scale_quality(engine::RayCaster& caster, const core::Grid& grid,
                                        const std::array<double, 9>& direction, engine::OrbitCamera cam,
                                        const engine::RaycastStyle& style, int W, int H, const MovingFramesOptions& o,
                                        const std::vector<double>& scales, int views) {
  std::vector<ScaleQuality> q;
  for (double s : scales) {
    ScaleQuality e{s, {}, {}};
    e.psnr_db.fill(std::numeric_limits<double>::infinity());
    e.ssim.fill(1);
    q.push_back(e);
  }
  std::vector<std::uint32_t> up(std::size_t(W) * std::size_t(H));
  const double step = o.degrees_per_frame * o.frames / std::max(1, views);
  for (int v = 0; v < views; ++v) {
    engine::OrbitCamera c = cam;
    c.azimuth_deg += step * (v + 0.5);
    const engine::CameraView view = engine::orbit_view(grid, direction, c);
    const engine::RaycastImage full = caster.render(view, style, W, H);
    for (ScaleQuality& e : q) {
      const int rw = std::max(1, int(std::lround(W * e.scale))), rh = std::max(1, int(std::lround(H * e.scale)));
      const engine::RaycastImage low = caster.render(view, style, rw, rh);
      const std::vector<std::uint8_t> mask = object_mask(full, low);
      for (std::size_t u = 0; u < std::size(kUpscales); ++u) {
        upscale(kUpscales[u], low, up, W, H);
        const engine::PictureError pe = engine::picture_error(full.rgba, up, mask, W, H, {W / 2, H / 2});
        e.psnr_db[u] = std::min(e.psnr_db[u], pe.psnr_db);
        e.ssim[u] = std::min(e.ssim[u], pe.ssim);
      }
    }
  }
  return q;
}

void print_scale_quality(std::ostream& out, const std::vector<ScaleQuality>& q, int views) {
  if (q.empty()) return;
  std::ostringstream log;
  log << std::fixed;
  for (std::size_t u = 0; u < std::size(kUpscales); ++u) {
    log << "moving   picture error by scale, " << to_string(kUpscales[u]) << " upscale (worst of " << views
        << " views, PSNR dB / SSIM):";
    for (const ScaleQuality& e : q)
      log << " " << std::setprecision(3) << e.scale << ": " << std::setprecision(1) << e.psnr_db[u] << " / "
          << std::setprecision(3) << e.ssim[u] << (&e == &q.back() ? "" : ",");
    log << "\n";
  }
  out << log.str();
}

}  // namespace isotouch::bench
