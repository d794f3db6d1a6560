#include "isotouch/engine/upscale.h"

#include <algorithm>
#include <vector>

namespace isotouch::engine {
namespace {

/// For each destination column (or row): the two source samples and the second's weight in 1/256.
struct Tap {
  int a, b;
  std::uint32_t wb;
};
std::vector<Tap> taps(int n_src, int n_dst) {
  std::vector<Tap> t(static_cast<std::size_t>(n_dst));
  for (int i = 0; i < n_dst; ++i) {
    const double s = (i + 0.5) * double(n_src) / double(n_dst) - 0.5;
    const int a = std::clamp(int(s >= 0 ? s : s - 1), 0, n_src - 1);  // floor, clamped
    const int b = std::min(a + 1, n_src - 1);
    const int wb = s <= 0 ? 0 : std::clamp(int((s - a) * 256 + 0.5), 0, 256);
    t[std::size_t(i)] = {a, b, std::uint32_t(wb)};
  }
  return t;
}

/// p + (q - p) * wq / 256 per 8-bit channel, two channels per 32-bit multiply (each lane's
/// 255 * 256 fits its 16 bits).
std::uint32_t lerp(std::uint32_t p, std::uint32_t q, std::uint32_t wq) {
  const std::uint32_t wp = 256 - wq;
  const std::uint32_t rb = (((p & 0x00ff00ffu) * wp + (q & 0x00ff00ffu) * wq + 0x00800080u) >> 8) & 0x00ff00ffu;
  const std::uint32_t ag = (((p >> 8) & 0x00ff00ffu) * wp + ((q >> 8) & 0x00ff00ffu) * wq + 0x00800080u) & 0xff00ff00u;
  return rb | ag;
}

}  // namespace

void upscale_bilinear(const std::uint32_t* src, int w, int h, std::uint32_t* dst, int W, int H) {
  const std::vector<Tap> tx = taps(w, W), ty = taps(h, H);
  std::vector<std::uint32_t> row(static_cast<std::size_t>(w));  // the two source rows blended
  int last_a = -1, last_b = -1;
  std::uint32_t last_w = 0;
  for (int y = 0; y < H; ++y) {
    const Tap& r = ty[std::size_t(y)];
    if (r.a != last_a || r.b != last_b || r.wb != last_w) {
      const std::uint32_t* ra = src + std::size_t(r.a) * std::size_t(w);
      const std::uint32_t* rb = src + std::size_t(r.b) * std::size_t(w);
      for (int x = 0; x < w; ++x) row[std::size_t(x)] = lerp(ra[x], rb[x], r.wb);
      last_a = r.a, last_b = r.b, last_w = r.wb;
    }
    std::uint32_t* out = dst + std::size_t(y) * std::size_t(W);
    for (int x = 0; x < W; ++x) {
      const Tap& c = tx[std::size_t(x)];
      out[x] = lerp(row[std::size_t(c.a)], row[std::size_t(c.b)], c.wb);
    }
  }
}

}  // namespace isotouch::engine
