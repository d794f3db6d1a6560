#include "isotouch/bench/moving_frames.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <ostream>
#include <sstream>

#include "isotouch/engine/upscale.h"
#include "isotouch/eval/stats.h"

namespace isotouch::bench {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

/// The object's pixels: a ray hit in the full picture or (nearest) in the reduced one.
std::vector<std::uint8_t> object_mask(const engine::RaycastImage& full, const engine::RaycastImage& low) {
  std::vector<std::uint8_t> m(full.depth.size(), 0);
  for (int y = 0; y < full.height; ++y)
    for (int x = 0; x < full.width; ++x) {
      const int lx = std::min(low.width - 1, x * low.width / full.width);
      const int ly = std::min(low.height - 1, y * low.height / full.height);
      const std::size_t i = std::size_t(y) * std::size_t(full.width) + std::size_t(x);
      m[i] = full.depth[i] >= 0 || low.depth[std::size_t(ly) * std::size_t(low.width) + std::size_t(lx)] >= 0;
    }
  return m;
}

}  // namespace

MovingFramesResult run_moving_frames(engine::RayCaster& caster, const core::Grid& grid,
                                     const std::array<double, 9>& direction, engine::OrbitCamera cam,
                                     const engine::RaycastStyle& style, int W, int H, const MovingFramesOptions& o,
                                     double max_scale) {
  MovingFramesResult r;
  engine::FrameBudget budget(engine::FrameBudgetOptions{o.budget_ms});
  std::vector<std::uint32_t> up(std::size_t(W) * std::size_t(H));
  const int every = std::max(2, o.compare_every);  // a compared frame is never the last: its stop is timed
  engine::CameraView view{};
  bool last_whole_size = false;
  for (int k = 0; k < o.frames; ++k) {
    cam.azimuth_deg += o.degrees_per_frame;
    view = engine::orbit_view(grid, direction, cam);
    const double s = std::min(budget.moving_scale(), max_scale);
    const int rw = std::max(1, int(std::lround(W * s))), rh = std::max(1, int(std::lround(H * s)));
    const auto t0 = Clock::now();
    const engine::RaycastImage low = caster.render(view, style, rw, rh);
    const double render_ms = ms_since(t0);
    if (rw != W || rh != H) engine::upscale_bilinear(low.rgba.data(), rw, rh, up.data(), W, H);
    const double ms = ms_since(t0);
    const double scaling = low.march_ms >= 0 ? std::min(render_ms, low.march_ms + std::max(0.0, low.shade_ms)) : render_ms;
    r.ms.push_back(ms);
    r.render_ms.push_back(render_ms);
    r.scales.push_back(double(rw) / double(W));
    budget.measured_whole(double(rw) / double(W), ms, ms - scaling);
    last_whole_size = rw == W && rh == H;
    if (k % every == every - 2 && k + 1 < o.frames) {
      const engine::RaycastImage full = caster.render(view, style, W, H);
      const std::vector<std::uint32_t>& shown = last_whole_size ? low.rgba : up;
      r.errors.push_back(engine::picture_error(full.rgba, shown, object_mask(full, low), W, H, {W / 2, H / 2}));
    }
  }
  // The view stops. A last frame at full resolution is the picture already (0 ms, no frame);
  // else the next frame is drawn whole at full resolution.
  if (last_whole_size || o.frames <= 0) return r;
  const auto t0 = Clock::now();
  const engine::RaycastImage still = caster.render(view, style, W, H);
  r.still_to_full_ms = ms_since(t0);
  r.still_frames = still.reused ? 0 : 1;
  return r;
}

void print_moving_frames(std::ostream& out, const MovingFramesResult& r, const MovingFramesOptions& o, int W, int H) {
  if (r.ms.empty()) return;
  std::ostringstream log;
  log << std::fixed << std::setprecision(1);
  const double med = eval::percentile(r.ms, 0.5), p95 = eval::percentile(r.ms, 0.95);
  const auto [lo, hi] = std::minmax_element(r.scales.begin(), r.scales.end());
  double psnr = std::numeric_limits<double>::infinity(), ssim = 1;  // inf: equal pictures
  int near = 0;
  bool object = true;
  for (const engine::PictureError& e : r.errors) object = object && e.pixels > 0;
  for (const engine::PictureError& e : r.errors) psnr = std::min(psnr, e.psnr_db), ssim = std::min(ssim, e.ssim), near = std::max(near, e.max_near);
  auto verdict = [](bool ok) { return ok ? "met" : "NOT met"; };
  log << "moving   " << r.ms.size() << " frames drawn whole while the view orbits " << o.degrees_per_frame << " deg per frame at "
      << W << "x" << H << ", scale chosen by the frame budget (" << o.budget_ms << " ms): scales " << std::setprecision(3) << *lo << "-" << *hi
      << " (last " << r.scales.back() << "; on a grid of 1/32)\n" << std::setprecision(1);
  log << "moving   the ray caster's part: median " << eval::percentile(r.render_ms, 0.5) << " ms, p95 "
      << eval::percentile(r.render_ms, 0.95) << " ms (the rest: the bilinear upscale to the window)\n";
  log << "verdict: moving frames median " << med << " ms: target <= " << o.budget_ms << " ms " << verdict(med <= o.budget_ms) << "\n";
  log << "verdict: moving frames p95 " << p95 << " ms: target <= " << 1.5 * o.budget_ms << " ms " << verdict(p95 <= 1.5 * o.budget_ms) << "\n";
  log << "verdict: view stopped to full resolution " << r.still_to_full_ms << " ms (" << r.still_frames
      << (r.still_frames == 1 ? " frame" : " frames") << " drawn whole): target <= 250 ms "
      << verdict(r.still_to_full_ms <= 250) << "\n";
  if (r.errors.empty()) return (void)(out << log.str());
  log << "verdict: moving frames against full resolution over the object's pixels (worst of " << r.errors.size()
      << " frames): PSNR " << psnr << " dB (target >= 30) SSIM " << std::setprecision(3) << ssim << " (target >= 0.95): "
      << verdict(psnr >= 30 && ssim >= 0.95 && object) << (object ? "" : " (a compared picture showed no object)") << "; largest channel error within 20 px of the centre " << near << " of 255\n";
  out << log.str();
}

}  // namespace isotouch::bench
