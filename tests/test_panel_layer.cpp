// The host's blend of the panels' premultiplied layer over a picture (apps/sculpt/panel_layer.h),
// against the formula in doubles: every alpha, picture byte and layer byte a premultiplied
// drawing can hold (up to its alpha + 1: the 8-bit rounding of ImGui's blending), and the
// rectangles (cut to the picture, overlaps blended once, nothing outside them touched).
// tests/sculpt_present.sh checks the whole window against the swapchain's drawing.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "isotouch/apps/sculpt/panel_layer.h"

namespace isotouch::sculpt {
namespace {

std::uint8_t expected(int d, int l, int a) {
  return std::uint8_t(std::min(255.0, l + std::floor(d * (255.0 - a) / 255.0 + 0.5)));
}

TEST(PanelLayer, BlendIsLayerPlusPictureTimesOneMinusAlpha) {
  // One row per alpha; per column a picture byte d and a layer byte l <= a + 1.
  const int w = 256 * 8, h = 256;
  std::vector<std::uint8_t> rows(std::size_t(w) * h * 4), layer(rows.size());
  for (int a = 0; a < h; ++a)
    for (int x = 0; x < w; ++x) {
      std::uint8_t* p = &rows[(std::size_t(a) * w + x) * 4];
      std::uint8_t* q = &layer[(std::size_t(a) * w + x) * 4];
      const int d = x / 8, lmax = std::min(255, a + 1);
      for (int c = 0; c < 3; ++c) {
        p[c] = std::uint8_t((d + 85 * c) % 256);
        q[c] = std::uint8_t((lmax * ((x + c) % 8)) / 7);
      }
      p[3] = 255;
      q[3] = std::uint8_t(a);
    }
  const std::vector<std::uint8_t> before = rows;
  compose_premultiplied(rows.data(), std::size_t(w) * 4, layer.data(), std::size_t(w) * 4, w, h, {{0, 0, w, h}});
  long wrong = 0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const int a = layer[i | 3u];
    const std::uint8_t want = (i & 3u) == 3u ? 255 : expected(before[i], layer[i], a);
    wrong += rows[i] != want;
  }
  EXPECT_EQ(wrong, 0) << "bytes off the formula";
}

TEST(PanelLayer, OnlyTheRectanglesOnceAndCut) {
  const int w = 40, h = 30;
  std::vector<std::uint8_t> rows(std::size_t(w) * h * 4, 200), layer(rows.size());
  for (std::size_t i = 0; i < layer.size(); i += 4) {
    layer[i] = layer[i + 1] = layer[i + 2] = 10;
    layer[i + 3] = 128;
  }
  // Two overlapping rectangles and one partly outside the picture.
  const std::vector<PixelRect> rects{{2, 3, 12, 10}, {8, 5, 20, 15}, {35, 25, 50, 40}};
  compose_premultiplied(rows.data(), std::size_t(w) * 4, layer.data(), std::size_t(w) * 4, w, h, rects);
  const std::uint8_t once = expected(200, 10, 128);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      bool in = false;
      for (const PixelRect& r : rects) in = in || (x >= r.x0 && x < r.x1 && y >= r.y0 && y < r.y1);
      EXPECT_EQ(rows[(std::size_t(y) * w + x) * 4], in ? once : 200) << "pixel (" << x << ", " << y << ")";
    }
}

}  // namespace
}  // namespace isotouch::sculpt
