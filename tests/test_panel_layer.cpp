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
  std::vector<std::uint32_t> rows32(std::size_t(w) * h), layer32(rows32.size());
  auto* rows = reinterpret_cast<std::uint8_t*>(rows32.data());
  auto* layer = reinterpret_cast<std::uint8_t*>(layer32.data());
  const std::size_t bytes = rows32.size() * 4;
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
  const std::vector<std::uint8_t> before(rows, rows + bytes);
  compose_premultiplied(rows, std::size_t(w) * 4, layer, std::size_t(w) * 4, w, h, {{0, 0, w, h}});
  long wrong = 0;
  for (std::size_t i = 0; i < bytes; ++i) {
    const int a = layer[i | 3u];
    const std::uint8_t want = (i & 3u) == 3u ? 255 : expected(before[i], layer[i], a);
    wrong += rows[i] != want;
  }
  EXPECT_EQ(wrong, 0) << "bytes off the formula";
}

TEST(PanelLayer, RowsAndLayerKeepTheirOwnStrides) {
  // Rows of 5 pixels padded to 7 and 9 pixels: a picture row at the layer's stride, or the
  // other way round, reads the wrong pixels.
  const int w = 5, h = 4, rs = 7, ls = 9;
  std::vector<std::uint32_t> rows(std::size_t(rs) * h), layer(std::size_t(ls) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < rs; ++x) rows[std::size_t(y) * rs + x] = 0xFF000000u | std::uint32_t(10 * y + x);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < ls; ++x) layer[std::size_t(y) * ls + x] = std::uint32_t(100 + 10 * y + x) << 8;  // G only, alpha 0
  const std::vector<std::uint32_t> before = rows;
  compose_premultiplied(reinterpret_cast<std::uint8_t*>(rows.data()), std::size_t(rs) * 4,
                        reinterpret_cast<const std::uint8_t*>(layer.data()), std::size_t(ls) * 4, w, h, {{0, 0, w, h}});
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < rs; ++x) {
      const std::uint32_t b = before[std::size_t(y) * rs + x];
      const std::uint32_t want = x < w ? b | (std::uint32_t(100 + 10 * y + x) << 8) : b;  // alpha 0: picture + layer
      EXPECT_EQ(rows[std::size_t(y) * rs + x], want) << "pixel (" << x << ", " << y << ")";
    }
}

TEST(PanelLayer, OnlyTheRectanglesOnceAndCut) {
  const int w = 40, h = 30;
  // Every byte 200 in the picture; the layer 10, 10, 10 at alpha 128.
  std::vector<std::uint32_t> rows32(std::size_t(w) * h, 0xC8C8C8C8u), layer32(rows32.size(), 0x800A0A0Au);
  auto* rows = reinterpret_cast<std::uint8_t*>(rows32.data());
  const auto* layer = reinterpret_cast<const std::uint8_t*>(layer32.data());
  // Two overlapping rectangles and three partly outside the picture: past its right and
  // bottom edges, before its left edge (a panel at the window's left edge: its box has a
  // pixel of margin) and above its top.
  const std::vector<PixelRect> rects{{2, 3, 12, 10}, {8, 5, 20, 15}, {35, 25, 50, 40}, {-5, 20, 4, 24}, {24, -3, 30, 2}};
  compose_premultiplied(rows, std::size_t(w) * 4, layer, std::size_t(w) * 4, w, h, rects);
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
