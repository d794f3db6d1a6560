#include "isotouch/engine/picture_error.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace isotouch::engine {
namespace {

int channel(std::uint32_t p, int c) { return int((p >> (8 * c)) & 255u); }
double luma(std::uint32_t p) { return 0.299 * channel(p, 0) + 0.587 * channel(p, 1) + 0.114 * channel(p, 2); }

/// SSIM of the luma over the object's pixels of one 8 x 8 window at (x0, y0).
double window_ssim(const std::vector<std::uint32_t>& a, const std::vector<std::uint32_t>& b,
                   const std::vector<std::uint8_t>& mask, int w, int x0, int y0) {
  constexpr double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0, n = 0;
  for (int y = y0; y < y0 + 8; ++y)
    for (int x = x0; x < x0 + 8; ++x) {
      const std::size_t i = std::size_t(y) * std::size_t(w) + std::size_t(x);
      if (!mask[i]) continue;
      const double u = luma(a[i]), v = luma(b[i]);
      sa += u, sb += v, saa += u * u, sbb += v * v, sab += u * v, ++n;
    }
  const double ma = sa / n, mb = sb / n;
  const double va = saa / n - ma * ma, vb = sbb / n - mb * mb, cov = sab / n - ma * mb;
  return ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
}

}  // namespace

PictureError picture_error(const std::vector<std::uint32_t>& ref, const std::vector<std::uint32_t>& test,
                           const std::vector<std::uint8_t>& mask, int w, int h, std::array<int, 2> probe, int near_px) {
  PictureError e;
  const std::size_t n = std::size_t(std::max(w, 0)) * std::size_t(std::max(h, 0));
  if (ref.size() < n || test.size() < n || mask.size() < n) return e;
  double sq = 0;
  const bool probe_inside = probe[0] >= 0 && probe[0] < w && probe[1] >= 0 && probe[1] < h;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * std::size_t(w) + std::size_t(x);
      if (!mask[i]) continue;
      ++e.pixels;
      const bool near = probe_inside && std::abs(x - probe[0]) <= near_px && std::abs(y - probe[1]) <= near_px;
      for (int c = 0; c < 3; ++c) {
        const int d = std::abs(channel(ref[i], c) - channel(test[i], c));
        sq += double(d) * d;
        if (near) e.max_near = std::max(e.max_near, d);
      }
    }
  const double mse = e.pixels > 0 ? sq / (3.0 * double(e.pixels)) : 0;
  e.psnr_db = mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : std::numeric_limits<double>::infinity();
  double sum = 0;
  long windows = 0;
  for (int y0 = 0; y0 + 8 <= h; y0 += 4)
    for (int x0 = 0; x0 + 8 <= w; x0 += 4) {
      int in = 0;
      for (int y = y0; y < y0 + 8; ++y)
        for (int x = x0; x < x0 + 8; ++x) in += mask[std::size_t(y) * std::size_t(w) + std::size_t(x)] != 0;
      if (2 * in < 64) continue;
      sum += window_ssim(ref, test, mask, w, x0, y0);
      ++windows;
    }
  e.ssim = windows > 0 ? sum / double(windows) : 1.0;
  return e;
}

}  // namespace isotouch::engine
