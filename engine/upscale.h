// upscale.h - a picture drawn at a lower resolution brought to the window's (bilinear).
#pragma once
#include <cstdint>

namespace isotouch::engine {

/// `src` (w x h RGBA8, R in the low byte, rows top to bottom) resampled to `dst` (W x H) by
/// bilinear interpolation per channel, pixel centres aligned (a pixel's centre at (x + 0.5) /
/// W of the width in both), edges clamped. w, h, W, H >= 1; dst holds W * H pixels.
void upscale_bilinear(const std::uint32_t* src, int w, int h, std::uint32_t* dst, int W, int H);

}  // namespace isotouch::engine
