// Upscaling (engine/upscale.h): bilinear against the analytic ramp it must reproduce; the
// depth-aware upscale against an analytic disc in front of a plane on a background.
#include "isotouch/engine/upscale.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace {
using isotouch::engine::upscale_bicubic;
using isotouch::engine::upscale_bilinear;
using isotouch::engine::upscale_depth_aware;

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

// An analytic scene sampled at pixel centres: a disc (radius 0.3 of the width, depth 1 m, red
// ramp along x) in front of a plane (the right half, depth 2 m, blue) on a background (depth
// -1, black). Colour and depth of the sample at (u, v) in [0, 1)^2.
struct Sample {
  std::uint32_t rgba;
  float depth;
};
Sample scene(double u, double v) {
  if ((u - 0.4) * (u - 0.4) + (v - 0.5) * (v - 0.5) < 0.09)
    return {std::uint32_t(std::lround(100 + 150 * u)) | 0xff000000u, 1.0f};
  if (u >= 0.5) return {0xffff0000u, 2.0f};  // blue
  return {0xff000000u, -1.0f};
}

// Each destination pixel shows the surface (or background) of the source sample nearest it:
// no pixel mixes the disc, the plane and the background (as bilinear does along their edges),
// and away from the edges it is bilinear's picture, bit for bit.
TEST(UpscaleDepthAware, NoPixelMixesAcrossTheSilhouetteOrADepthStep) {
  const int w = 40, h = 30, W = 160, H = 120;
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(std::size_t(W * H)), bil(dst.size());
  std::vector<float> depth(src.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Sample s = scene((x + 0.5) / w, (y + 0.5) / h);
      src[std::size_t(y * w + x)] = s.rgba;
      depth[std::size_t(y * w + x)] = s.depth;
    }
  upscale_depth_aware(src.data(), depth.data(), w, h, dst.data(), W, H);
  upscale_bilinear(src.data(), w, h, bil.data(), W, H);
  int mixed_by_bilinear = 0;
  for (int Y = 0; Y < H; ++Y)
    for (int X = 0; X < W; ++X) {
      const std::uint32_t p = dst[std::size_t(Y * W + X)], b = bil[std::size_t(Y * W + X)];
      // The source sample nearest this pixel's centre.
      const int x = std::min(w - 1, (2 * X + 1) * w / (2 * W)), y = std::min(h - 1, (2 * Y + 1) * h / (2 * H));
      const float d = depth[std::size_t(y * w + x)];
      const bool red = (p & 255u) > 0, blue = (p >> 16 & 255u) > 0;
      if (d < 0) { EXPECT_EQ(p, 0xff000000u) << "background at " << X << "," << Y; }
      if (d == 2.0f) { EXPECT_EQ(p, 0xffff0000u) << "plane at " << X << "," << Y; }
      if (d == 1.0f) { EXPECT_TRUE(red && !blue && (p & 255u) >= 100) << "disc at " << X << "," << Y << ": " << std::hex << p; }
      mixed_by_bilinear += (d < 0 && b != 0xff000000u) || (d == 2.0f && b != 0xffff0000u);
      // Away from the edges (all four samples on one surface) the two upscales agree.
      const double u = (X + 0.5) * w / W - 0.5, v = (Y + 0.5) * h / H - 0.5;
      const int x0 = std::clamp(int(std::floor(u)), 0, w - 1), y0 = std::clamp(int(std::floor(v)), 0, h - 1);
      const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
      const float d4[4] = {depth[std::size_t(y0 * w + x0)], depth[std::size_t(y0 * w + x1)], depth[std::size_t(y1 * w + x0)],
                           depth[std::size_t(y1 * w + x1)]};
      if (d4[0] == d4[1] && d4[0] == d4[2] && d4[0] == d4[3]) { EXPECT_EQ(p, b) << X << "," << Y; }
    }
  EXPECT_GT(mixed_by_bilinear, 100) << "the scene's edges are where bilinear mixes (the test's premise)";
}

TEST(UpscaleDepthAware, SameSizeIsACopy) {
  const int w = 5, h = 3;
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(src.size());
  std::vector<float> depth(src.size());
  for (int i = 0; i < w * h; ++i) src[std::size_t(i)] = std::uint32_t(i * 2654435761u), depth[std::size_t(i)] = float(i % 3) - 1.0f;
  upscale_depth_aware(src.data(), depth.data(), w, h, dst.data(), w, h);
  EXPECT_EQ(dst, src);
}

// Catmull-Rom reproduces quadratics (Keys 1981): a parabola per channel (R along x, G along y),
// whose curvature bilinear misses by up to 2 levels between samples, comes out within 0.6.
TEST(UpscaleBicubic, AParabolaStaysAParabola) {
  const int w = 9, h = 7, W = 36, H = 28;
  const auto r = [](double x) { return 8 * (x - 4) * (x - 4); };  // 0-128
  const auto g = [](double y) { return 12 * (y - 3) * (y - 3); };  // 0-108
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(std::size_t(W * H)), bil(dst.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      src[std::size_t(y * w + x)] = std::uint32_t(r(x)) | std::uint32_t(g(y)) << 8 | 0xff000000u;
  upscale_bicubic(src.data(), w, h, dst.data(), W, H);
  upscale_bilinear(src.data(), w, h, bil.data(), W, H);
  double worst_bilinear = 0;
  for (int Y = 6; Y < H - 6; ++Y)  // at least one source sample from the clamped edges
    for (int X = 6; X < W - 6; ++X) {
      const double u = (X + 0.5) * w / W - 0.5, v = (Y + 0.5) * h / H - 0.5;
      const std::uint32_t p = dst[std::size_t(Y * W + X)], b = bil[std::size_t(Y * W + X)];
      EXPECT_NEAR(double(p & 255u), r(u), 0.6) << X << "," << Y;
      EXPECT_NEAR(double(p >> 8 & 255u), g(v), 0.6) << X << "," << Y;
      EXPECT_EQ(p >> 24, 255u);
      worst_bilinear = std::max({worst_bilinear, std::abs(double(b & 255u) - r(u)), std::abs(double(b >> 8 & 255u) - g(v))});
    }
  EXPECT_GT(worst_bilinear, 1.5) << "the parabola's curvature is what bilinear misses (the test's premise)";
}

TEST(UpscaleBicubic, SameSizeIsACopyAndOvershootIsClamped) {
  const int w = 5, h = 3;
  std::vector<std::uint32_t> src(std::size_t(w * h)), dst(src.size());
  for (int i = 0; i < w * h; ++i) src[std::size_t(i)] = std::uint32_t(i * 2654435761u);
  upscale_bicubic(src.data(), w, h, dst.data(), w, h);
  EXPECT_EQ(dst, src);
  // A step 0 -> 255 rings past both levels: clamped, never wrapped into another channel.
  std::vector<std::uint32_t> step{0xff000000u, 0xff000000u, 0xffffffffu, 0xffffffffu}, big(16);
  upscale_bicubic(step.data(), 4, 1, big.data(), 16, 1);
  for (int i = 1; i < 16; ++i) EXPECT_GE(big[std::size_t(i)] & 255u, big[std::size_t(i - 1)] & 255u) << i;
  for (std::uint32_t p : big) EXPECT_EQ(p >> 24, 255u);
}

}  // namespace
