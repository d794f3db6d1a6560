// The reduced-resolution picture's error (engine/picture_error.h) against figures computed
// by hand for pictures the test builds.
#include "isotouch/engine/picture_error.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

namespace {
using isotouch::engine::picture_error;

std::uint32_t rgb(int r, int g, int b) { return std::uint32_t(r) | std::uint32_t(g) << 8 | std::uint32_t(b) << 16 | 0xff000000u; }

struct Pics {
  int w = 64, h = 48;
  std::vector<std::uint32_t> ref, test;
  std::vector<std::uint8_t> mask;
  Pics() {
    ref.resize(std::size_t(w * h)), mask.assign(std::size_t(w * h), 0);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = std::size_t(y * w + x);
        ref[i] = rgb(40 + (x * 3 + y * 5) % 150, 60 + (x * 7) % 120, 80 + (y * 11) % 100);  // texture
        mask[i] = x >= 8 && x < 56 && y >= 8 && y < 40;  // the object
      }
    test = ref;
  }
};

TEST(PictureError, EqualPicturesAreInfiniteAndOne) {
  Pics p;
  const auto e = picture_error(p.ref, p.test, p.mask, p.w, p.h, {32, 24});
  EXPECT_EQ(e.pixels, 48L * 32L);
  EXPECT_TRUE(std::isinf(e.psnr_db));
  EXPECT_DOUBLE_EQ(e.ssim, 1.0);
  EXPECT_EQ(e.max_near, 0);
}

TEST(PictureError, AUniformOffsetGivesTheAnalyticPsnrAndOnlyTheMaskCounts) {
  Pics p;
  for (std::size_t i = 0; i < p.test.size(); ++i) {
    const std::uint32_t c = p.ref[i];
    p.test[i] = p.mask[i] ? rgb(int(c & 255) + 5, int(c >> 8 & 255) - 5, int(c >> 16 & 255) + 5) : rgb(255, 0, 255);
  }
  const auto e = picture_error(p.ref, p.test, p.mask, p.w, p.h, {32, 24});
  EXPECT_NEAR(e.psnr_db, 20 * std::log10(255.0 / 5.0), 1e-9) << "MSE 25 over the object, the outside ignored";
  EXPECT_EQ(e.max_near, 5);
  EXPECT_GT(e.ssim, 0.95) << "an offset of 5 keeps the structure";
  const auto far = picture_error(p.ref, p.test, p.mask, p.w, p.h, {-100, -100});
  EXPECT_EQ(far.max_near, 0) << "no object pixel near a probe outside the picture";
  const auto edge = picture_error(p.ref, p.test, p.mask, p.w, p.h, {-5, 10});
  EXPECT_EQ(edge.max_near, 0) << "a probe just outside the picture has no near pixels";
}

// SSIM of a window whose test luma is the reference's plus a constant c: the structure and
// contrast terms are 1, the luminance term (2 ma mb + C1) / (ma^2 + mb^2 + C1) with mb = ma + c.
TEST(PictureError, SsimOfALumaOffsetIsTheLuminanceTerm) {
  const int w = 8, h = 8;
  std::vector<std::uint32_t> ref(64), test(64);
  std::vector<std::uint8_t> mask(64, 1);
  double sum = 0;
  for (int i = 0; i < 64; ++i) {
    const int g = 60 + (i * 37) % 100;
    ref[std::size_t(i)] = rgb(g, g, g), test[std::size_t(i)] = rgb(g + 20, g + 20, g + 20);
    sum += g;
  }
  const double ma = sum / 64, mb = ma + 20, c1 = (0.01 * 255) * (0.01 * 255);
  const double want = (2 * ma * mb + c1) / (ma * ma + mb * mb + c1);
  const auto e = picture_error(ref, test, mask, w, h, {0, 0});
  EXPECT_NEAR(e.ssim, want, 1e-9);
  EXPECT_NEAR(e.psnr_db, 20 * std::log10(255.0 / 20.0), 1e-9);
}

TEST(PictureError, ScrambledStructureLowersSsim) {
  Pics p;
  for (int y = 0; y < p.h; ++y)
    for (int x = 0; x < p.w; ++x) p.test[std::size_t(y * p.w + x)] = p.ref[std::size_t(y * p.w + (p.w - 1 - x))];
  const auto e = picture_error(p.ref, p.test, p.mask, p.w, p.h, {32, 24});
  EXPECT_LT(e.ssim, 0.6);
  EXPECT_LT(e.psnr_db, 20);
}

}  // namespace
