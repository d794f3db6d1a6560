#include "isotouch/bench/moving_frames.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <iterator>
#include <limits>
#include <ostream>
#include <sstream>

#include "isotouch/engine/upscale.h"
#include "isotouch/eval/stats.h"

namespace isotouch::bench {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

/// The worst of the compared frames: the lowest PSNR and SSIM, the largest error near the probe.
struct Worst {
  double psnr = std::numeric_limits<double>::infinity(), ssim = 1;  // inf: equal pictures
  int near = 0;
  bool object = true;  // every compared picture showed the object
};
Worst worst(const std::vector<engine::PictureError>& errors) {
  Worst w;
  for (const engine::PictureError& e : errors) {
    w.psnr = std::min(w.psnr, e.psnr_db), w.ssim = std::min(w.ssim, e.ssim), w.near = std::max(w.near, e.max_near);
    w.object = w.object && e.pixels > 0;
  }
  return w;
}

}  // namespace

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

void upscale(Upscale u, const engine::RaycastImage& low, std::vector<std::uint32_t>& out, int W, int H) {
  switch (u) {
    case Upscale::bilinear: return engine::upscale_bilinear(low.rgba.data(), low.width, low.height, out.data(), W, H);
    case Upscale::bicubic: return engine::upscale_bicubic(low.rgba.data(), low.width, low.height, out.data(), W, H);
    case Upscale::depth_aware:
      return engine::upscale_depth_aware(low.rgba.data(), low.depth.data(), low.width, low.height, out.data(), W, H);
  }
}

const char* to_string(Upscale u) {
  switch (u) {
    case Upscale::bilinear: return "bilinear";
    case Upscale::bicubic: return "bicubic";
    case Upscale::depth_aware: return "depth-aware";
  }
  return "?";
}

MovingFramesResult run_moving_frames(engine::RayCaster& caster, const core::Grid& grid,
                                     const std::array<double, 9>& direction, engine::OrbitCamera cam,
                                     const engine::RaycastStyle& style, int W, int H, const MovingFramesOptions& o,
                                     double max_scale) {
  MovingFramesResult r;
  engine::FrameBudgetOptions bo;
  bo.budget_ms = o.budget_ms;
  bo.target = o.target;
  engine::FrameBudget budget(bo);
  std::vector<std::uint32_t> up(std::size_t(W) * std::size_t(H)), other(up.size());
  const int every = std::max(2, o.compare_every);  // a compared frame is never the last: its stop is timed
  engine::CameraView view{};
  bool last_whole_size = false;
  int last_w = W, last_h = H;
  for (int k = 0; k < o.frames; ++k) {
    cam.azimuth_deg += o.degrees_per_frame;
    view = engine::orbit_view(grid, direction, cam);
    const double s = std::min(budget.moving_scale(), max_scale);
    const int rw = std::max(1, int(std::lround(W * s))), rh = std::max(1, int(std::lround(H * s)));
    const auto t0 = Clock::now();
    const engine::RaycastImage low = caster.render(view, style, rw, rh);
    const double render_ms = ms_since(t0);
    if (rw != W || rh != H) upscale(o.upscale, low, up, W, H);
    const double ms = ms_since(t0);
    const double scaling = low.march_ms >= 0 ? std::min(render_ms, low.march_ms + std::max(0.0, low.shade_ms)) : render_ms;
    r.ms.push_back(ms);
    r.render_ms.push_back(render_ms);
    r.scales.push_back(double(rw) / double(W));
    budget.measured_whole(double(rw) / double(W), ms, ms - scaling);
    last_whole_size = rw == W && rh == H;
    last_w = rw, last_h = rh;
    if (k % every == every - 2 && k + 1 < o.frames) {
      const engine::RaycastImage full = caster.render(view, style, W, H);
      const std::vector<std::uint32_t>& shown = last_whole_size ? low.rgba : up;
      const std::vector<std::uint8_t> mask = object_mask(full, low);
      r.errors.push_back(engine::picture_error(full.rgba, shown, mask, W, H, {W / 2, H / 2}));
      for (std::size_t u = 0; u < std::size(kUpscales); ++u) {
        if (!last_whole_size) upscale(kUpscales[u], low, other, W, H);
        r.errors_by[u].push_back(engine::picture_error(full.rgba, last_whole_size ? low.rgba : other, mask, W, H, {W / 2, H / 2}));
      }
    }
  }
  // The view stops. A last frame at full resolution is the picture already (0 ms, no frame);
  // else it is refined a band of rows per frame within the budget.
  if (last_whole_size || o.frames <= 0) return r;
  r.still = refine_still(caster, view, style, W, H, last_w, last_h, budget, up);
  r.still_to_full_ms = r.still.total_ms();
  r.still_frames = int(r.still.ms.size());
  return r;
}

void print_moving_frames(std::ostream& out, const MovingFramesResult& r, const MovingFramesOptions& o, int W, int H) {
  if (r.ms.empty()) return;
  std::ostringstream log;
  log << std::fixed << std::setprecision(1);
  const double med = eval::percentile(r.ms, 0.5), p95 = eval::percentile(r.ms, 0.95);
  const auto [lo, hi] = std::minmax_element(r.scales.begin(), r.scales.end());
  auto verdict = [](bool ok) { return ok ? "met" : "NOT met"; };
  log << "moving   " << r.ms.size() << " frames drawn whole while the view orbits " << o.degrees_per_frame << " deg per frame at "
      << W << "x" << H << ", scale chosen by the frame budget (" << o.budget_ms << " ms): scales " << std::setprecision(3) << *lo << "-" << *hi
      << " (last " << r.scales.back() << "; on a grid of 1/32)\n" << std::setprecision(1);
  log << "moving   the ray caster's part: median " << eval::percentile(r.render_ms, 0.5) << " ms, p95 "
      << eval::percentile(r.render_ms, 0.95) << " ms (the rest: the upscale to the window)\n";
  log << "verdict: moving frames median " << med << " ms: target <= " << o.budget_ms << " ms " << verdict(med <= o.budget_ms) << "\n";
  log << "verdict: moving frames p95 " << p95 << " ms: target <= " << 1.5 * o.budget_ms << " ms " << verdict(p95 <= 1.5 * o.budget_ms) << "\n";
  log << "verdict: view stopped to full resolution " << r.still_to_full_ms << " ms (" << r.still_frames
      << (r.still_frames == 1 ? " frame" : " frames") << " in bands of rows): target <= 250 ms: "
      << verdict(r.still_to_full_ms <= 250) << "; the full frame bit for bit: "
      << (r.still_frames == 0 ? "yes (drawn whole while moving)" : r.still.equal ? "yes" : "NO") << "\n";
  // Each band is a frame: the largest against the budget (the refinement's promise).
  if (r.still_frames > 0) {
    const auto big = std::max_element(r.still.ms.begin(), r.still.ms.end()) - r.still.ms.begin();
    log << "verdict: refinement bands: the largest " << r.still.ms[std::size_t(big)] << " ms (band " << big + 1 << " of "
        << r.still_frames << ", " << r.still.rows[std::size_t(big)] << " of " << H << " rows): each <= " << o.budget_ms
        << " ms (the frame budget): " << verdict(r.still.max_ms() <= o.budget_ms) << "\n";
  } else {
    log << "verdict: refinement bands: none (drawn whole while moving): each <= " << o.budget_ms << " ms (the frame budget): met\n";
  }
  if (!r.still.ms.empty()) {
    log << "moving   the bands (rows: ms):";
    for (std::size_t i = 0; i < r.still.ms.size(); ++i) log << " " << r.still.rows[i] << ": " << r.still.ms[i];
    log << "\n";
  }
  if (r.errors.empty()) return (void)(out << log.str());
  const Worst e = worst(r.errors);
  log << "verdict: moving frames against full resolution over the object's pixels (worst of " << r.errors.size()
      << " frames, " << to_string(o.upscale) << " upscale): PSNR " << e.psnr << " dB (target >= 30) SSIM " << std::setprecision(3) << e.ssim
      << " (target >= 0.95): " << verdict(e.psnr >= 30 && e.ssim >= 0.95 && e.object)
      << (e.object ? "" : " (a compared picture showed no object)") << "; largest channel error within 20 px of the centre "
      << e.near << " of 255\n" << std::setprecision(1);
  for (std::size_t u = 0; u < std::size(kUpscales); ++u) {  // the same low pictures, each upscale
    const Worst b = worst(r.errors_by[u]);
    log << "moving   the same frames upscaled " << to_string(kUpscales[u]) << (kUpscales[u] == o.upscale ? " (shown)" : "")
        << ": PSNR " << b.psnr << " dB SSIM " << std::setprecision(3) << b.ssim << std::setprecision(1)
        << "; largest channel error within 20 px of the centre " << b.near << " of 255\n";
  }
  out << log.str();
}

}  // namespace isotouch::bench
