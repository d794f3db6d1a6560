// Bilinear upscaling (engine/upscale.h) against the analytic ramp it must reproduce.
#include "isotouch/engine/upscale.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

namespace {
using isotouch::engine::upscale_bilinear;

std::uint32_t grey(int v) { return std::uint32_t(v) * 0x010101u | 0xff000000u; }

TEST(UpscaleBilinear, ARampStaysARampBetweenTheEdgeSamples) {
  // A horizontal ramp of 16 samples, value 16 * x + 8 at pixel centre x + 0.5.
  const int w = 16, h = 4, W = 64, H = 16;
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(std::size_t(W * H));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) src[std::size_t(y * w + x)] = grey(16 * x + 8);
  upscale_bilinear(src.data(), w, h, dst.data(), W, H);
  for (int y = 0; y < H; ++y)
    for (int X = 2; X < W - 2; ++X) {  // between the first and last source centres
      const double u = (X + 0.5) * w / W;  // in source pixels
      const double want = 16 * (u - 0.5) + 8;
      const int got = int(dst[std::size_t(y * W + X)] & 255u);
      EXPECT_NEAR(got, want, 1.0) << "pixel " << X << " of row " << y;
      EXPECT_EQ(dst[std::size_t(y * W + X)] >> 24, 255u) << "alpha";
    }
}

TEST(UpscaleBilinear, SameSizeIsACopyAndEdgesAreClamped) {
  const int w = 5, h = 3;
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(std::size_t(w * h));
  for (int i = 0; i < w * h; ++i) src[std::size_t(i)] = std::uint32_t(i * 2654435761u);
  upscale_bilinear(src.data(), w, h, dst.data(), w, h);
  EXPECT_EQ(dst, src);
  std::vector<std::uint32_t> one{grey(200)}, big(100);
  upscale_bilinear(one.data(), 1, 1, big.data(), 10, 10);
  for (std::uint32_t p : big) EXPECT_EQ(p, grey(200));
}

}  // namespace
