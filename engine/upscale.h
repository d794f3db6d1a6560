// upscale.h - a picture drawn at a lower resolution brought to the window's: bilinear, or
// bilinear that does not blend across the object's silhouette and depth steps (the low
// picture's depth guides it).
#pragma once
#include <cstdint>

namespace isotouch::engine {

/// `src` (w x h RGBA8, R in the low byte, rows top to bottom) resampled to `dst` (W x H) by
/// bilinear interpolation per channel, pixel centres aligned (a pixel's centre at (x + 0.5) /
/// W of the width in both), edges clamped. w, h, W, H >= 1; dst holds W * H pixels.
void upscale_bilinear(const std::uint32_t* src, int w, int h, std::uint32_t* dst, int W, int H);

/// As upscale_bilinear, guided by `depth` (w x h, the ray parameter t of the hit [m], < 0
/// where the ray missed): each destination pixel blends only those of its four source
/// samples that lie on the same side of the silhouette as the nearest one (hit or miss) and,
/// for hits, within `rel_depth` of its depth (|t - t_nearest| <= rel_depth * t_nearest), with
/// their bilinear weights renormalised. Where all four agree the result is upscale_bilinear's,
/// bit for bit; the silhouette and depth steps stay sharp at the source's resolution instead
/// of mixing object and background.
void upscale_depth_aware(const std::uint32_t* src, const float* depth, int w, int h, std::uint32_t* dst, int W,
                         int H, float rel_depth = 0.05f);

/// As upscale_bilinear, by Catmull-Rom cubic convolution per channel (Keys 1981, a = -0.5):
/// four source samples per axis, exact on linear ramps like bilinear but sharper (less blur
/// of the detail that survives the lower resolution); rounded and clamped to [0, 255].
void upscale_bicubic(const std::uint32_t* src, int w, int h, std::uint32_t* dst, int W, int H);

}  // namespace isotouch::engine
