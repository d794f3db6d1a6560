// picture_error.h - how far a picture drawn at reduced resolution is from the full one.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

namespace isotouch::engine {

/// Differences over the object's pixels (the mask), RGBA8 pictures of the same w x h.
struct PictureError {
  long pixels = 0;        ///< pixels in the mask
  double psnr_db = 0;     ///< 10 log10(255^2 / mean squared R, G, B difference); +inf when equal
  double ssim = 1;        ///< mean SSIM of the luma (Wang et al. 2004, 8x8 windows, stride 4, each over its mask pixels) over windows at least half in the mask
  int max_near = 0;       ///< the largest channel difference (0-255) within `near_px` of the probe's pixel
};

/// `mask`: w * h bytes, non-zero where the object is (a ray hit the surface in either picture).
/// `probe`: the probe's pixel (x, y); outside the picture: max_near stays 0. An empty mask
/// gives pixels 0 (and PSNR inf, SSIM 1: a caller judging pictures must check pixels first).
PictureError picture_error(const std::vector<std::uint32_t>& ref, const std::vector<std::uint32_t>& test,
                           const std::vector<std::uint8_t>& mask, int w, int h, std::array<int, 2> probe,
                           int near_px = 20);

}  // namespace isotouch::engine
