// moving_frames.h - frames drawn whole while the view moves, at the scale the frame-budget
// controller (engine/frame_budget.h) chooses, against the budget, with the image error over
// the object's pixels and the time from the view stopping to the full-resolution picture.
#pragma once
#include <array>
#include <cstdint>
#include <iosfwd>
#include <iterator>
#include <vector>

#include "isotouch/bench/still_refine.h"
#include "isotouch/engine/frame_budget.h"
#include "isotouch/engine/picture_error.h"
#include "isotouch/engine/raycast.h"

namespace isotouch::bench {

/// The upscales of engine/upscale.h.
enum class Upscale { bilinear, bicubic, depth_aware };
const char* to_string(Upscale u);
constexpr Upscale kUpscales[] = {Upscale::bilinear, Upscale::bicubic, Upscale::depth_aware};

struct MovingFramesOptions {
  double budget_ms = 33;          ///< the frame budget [ms]
  int frames = 60;                ///< moving frames drawn
  double degrees_per_frame = 3;   ///< the orbit's azimuth step per frame [deg]
  int compare_every = 10;         ///< every this many frames (at least 2) the same view is drawn at scale 1 too (not timed)
  Upscale upscale = Upscale::bilinear;  ///< the upscale shown (and timed)
  double target = 0.9;            ///< engine::FrameBudgetOptions::target: the share of the budget a frame is planned to take
};

/// The object's pixels of a W x H picture: a ray hit in `full` or (nearest) in `low`.
std::vector<std::uint8_t> object_mask(const engine::RaycastImage& full, const engine::RaycastImage& low);
/// `low` brought to W x H into `out` (W * H pixels) by upscale `u` (engine/upscale.h).
void upscale(Upscale u, const engine::RaycastImage& low, std::vector<std::uint32_t>& out, int W, int H);

struct MovingFramesResult {
  std::vector<double> ms;        ///< each moving frame: render at the chosen scale + the upscale shown [ms]
  std::vector<double> render_ms; ///< of which the ray caster's render() [ms]
  std::vector<double> scales;    ///< the scale each was drawn at
  std::vector<engine::PictureError> errors;  ///< the compared frames' error over the object's pixels (the upscale shown)
  /// The same frames with each upscale (kUpscales' order; the shown one's equal to `errors`).
  std::vector<engine::PictureError> errors_by[std::size(kUpscales)];
  double still_to_full_ms = 0;   ///< from the view stopping to the full-resolution picture [ms]
  int still_frames = 0;          ///< frames refining it (0: the last moving frame was at full resolution)
  StillRefinement still;         ///< those frames (bench/still_refine.h)
};

/// Orbits `cam` about its target in `caster`'s volume (`grid`, `direction`: its frame, see
/// engine::orbit_view) at a W x H window, each frame at the budget's scale, at most
/// `max_scale` (what one storage binding of the device holds at that window); the probe's
/// pixel for the error's near figure is the picture's centre (the orbit's target). The view
/// stopping after a frame already at full resolution costs no frame (0 ms); else it is
/// refined by refine_still.
MovingFramesResult run_moving_frames(engine::RayCaster& caster, const core::Grid& grid,
                                     const std::array<double, 9>& direction, engine::OrbitCamera cam,
                                     const engine::RaycastStyle& style, int W, int H, const MovingFramesOptions& o,
                                     double max_scale = 1.0);

/// The figures and the verdicts: moving frames median <= budget and p95 <= 1.5 budget, full
/// resolution within 250 ms of the view stopping (and whether it ended equal to a full frame),
/// the largest refining band (a frame) within the budget, PSNR >= 30 dB and SSIM >= 0.95
/// (worst compared frame).
void print_moving_frames(std::ostream& log, const MovingFramesResult& r, const MovingFramesOptions& o, int W, int H);

}  // namespace isotouch::bench
