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

// Each channel its own ramp (R along x, G along y, B along x + y, A fixed at 255, the lanes'
// largest value): every lane and both directions interpolate, none bleeds into another.
TEST(UpscaleBilinear, EveryChannelAndBothAxesInterpolate) {
  const int w = 9, h = 7, W = 36, H = 28;
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(std::size_t(W * H));
  const auto r = [](double x) { return 255.0 * x / 8; };
  const auto g = [](double y) { return 255.0 * y / 6; };
  const auto b = [](double x, double y) { return 255.0 * (x + y) / 14; };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      src[std::size_t(y * w + x)] = std::uint32_t(std::lround(r(x))) | std::uint32_t(std::lround(g(y))) << 8 |
                                    std::uint32_t(std::lround(b(x, y))) << 16 | 0xff000000u;
  upscale_bilinear(src.data(), w, h, dst.data(), W, H);
  for (int Y = 2; Y < H - 2; ++Y)
    for (int X = 2; X < W - 2; ++X) {
      const double u = (X + 0.5) * w / W - 0.5, v = (Y + 0.5) * h / H - 0.5;  // source coordinates
      const std::uint32_t p = dst[std::size_t(Y * W + X)];
      EXPECT_NEAR(double(p & 255u), r(u), 1.5) << X << "," << Y;
      EXPECT_NEAR(double(p >> 8 & 255u), g(v), 1.5) << X << "," << Y;
      EXPECT_NEAR(double(p >> 16 & 255u), b(u, v), 1.5) << X << "," << Y;
      EXPECT_EQ(p >> 24, 255u);
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
