// scale_quality.h - how the picture error over the object's pixels falls with the ray
// caster's scale, for each upscale: what a frame budget would have to allow for a given
// picture quality (isotouch-sculpt --bench, beside the moving frames).
#pragma once
#include <array>
#include <iosfwd>
#include <vector>

#include "isotouch/bench/moving_frames.h"

namespace isotouch::bench {

struct ScaleQuality {
  double scale = 1;                                ///< the fraction of the window's resolution drawn
  std::array<double, std::size(kUpscales)> psnr_db{};  ///< per upscale (kUpscales' order): the worst view's PSNR [dB]
  std::array<double, std::size(kUpscales)> ssim{};     ///< per upscale: the worst view's SSIM
};

/// Each of `scales` at `views` views of the orbit (`o.degrees_per_frame` * `o.frames` /
/// `views` apart, from `cam`), drawn at that scale and at full resolution (not timed), the
/// error of each upscale against full resolution over the object's pixels (as
/// run_moving_frames compares).
std::vector<ScaleQuality> scale_quality(engine::RayCaster& caster, const core::Grid& grid,
                                        const std::array<double, 9>& direction, engine::OrbitCamera cam,
                                        const engine::RaycastStyle& style, int W, int H, const MovingFramesOptions& o,
                                        const std::vector<double>& scales, int views = 3);

/// One line per upscale: PSNR / SSIM at each scale.
void print_scale_quality(std::ostream& log, const std::vector<ScaleQuality>& q, int views);

}  // namespace isotouch::bench
