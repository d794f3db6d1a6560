#include "isotouch/engine/upscale.h"

#include <algorithm>
#include <cmath>
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

/// The bilinear weights of a 2 x 2 neighbourhood renormalised over the samples `keep` marks
/// (order: a-row a-col, a-row b-col, b-row a-col, b-row b-col), per channel, rounded.
std::uint32_t blend_kept(const std::uint32_t p[4], const bool keep[4], std::uint32_t wx, std::uint32_t wy) {
  const std::uint32_t w[4] = {(256 - wx) * (256 - wy), wx * (256 - wy), (256 - wx) * wy, wx * wy};
  std::uint32_t sum = 0, acc[4] = {0, 0, 0, 0};
  for (int k = 0; k < 4; ++k) {
    if (!keep[k]) continue;
    sum += w[k];
    for (int c = 0; c < 4; ++c) acc[c] += (p[k] >> (8 * c) & 255u) * w[k];
  }
  std::uint32_t out = 0;
  for (int c = 0; c < 4; ++c) out |= ((acc[c] + sum / 2) / sum) << (8 * c);
  return out;
}

/// For each destination column (or row): the first of its four source samples (unclamped)
/// and their Catmull-Rom weights in 1/1024 (summing to 1024).
struct Taps4 {
  int first;
  std::int32_t wt[4];
};
std::vector<Taps4> taps4(int n_src, int n_dst) {
  std::vector<Taps4> t(static_cast<std::size_t>(n_dst));
  for (int i = 0; i < n_dst; ++i) {
    const double s = (i + 0.5) * double(n_src) / double(n_dst) - 0.5;
    const double f = std::floor(s), u = s - f;
    const double w[4] = {((-0.5 * u + 1.0) * u - 0.5) * u, (1.5 * u - 2.5) * u * u + 1.0,
                         ((-1.5 * u + 2.0) * u + 0.5) * u, (0.5 * u - 0.5) * u * u};
    Taps4& o = t[std::size_t(i)];
    o.first = int(f) - 1;
    int sum = 0;
    for (int k = 0; k < 3; ++k) sum += o.wt[k] = std::int32_t(std::lround(w[k] * 1024));
    o.wt[3] = 1024 - sum;
  }
  return t;
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

/// Rows first (the source's w columns at H rows, 4 channels as int in 1/1024), then columns.
void upscale_bicubic(const std::uint32_t* src, int w, int h, std::uint32_t* dst, int W, int H) {
  const std::vector<Taps4> tx = taps4(w, W), ty = taps4(h, H);
  std::vector<std::int32_t> row(std::size_t(w) * 4);
  const auto clamp_to = [](int v, int n) { return std::clamp(v, 0, n - 1); };
  for (int y = 0; y < H; ++y) {
    const Taps4& r = ty[std::size_t(y)];
    const std::uint32_t* rows[4];
    for (int k = 0; k < 4; ++k) rows[k] = src + std::size_t(clamp_to(r.first + k, h)) * std::size_t(w);
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 4; ++c) {
        std::int32_t acc = 0;
        for (int k = 0; k < 4; ++k) acc += std::int32_t(rows[k][x] >> (8 * c) & 255u) * r.wt[k];
        row[std::size_t(x) * 4 + std::size_t(c)] = acc;
      }
    std::uint32_t* out = dst + std::size_t(y) * std::size_t(W);
    for (int x = 0; x < W; ++x) {
      const Taps4& t = tx[std::size_t(x)];
      std::uint32_t px = 0;
      for (int c = 0; c < 4; ++c) {
        std::int64_t acc = 0;
        for (int k = 0; k < 4; ++k) acc += std::int64_t(row[std::size_t(clamp_to(t.first + k, w)) * 4 + std::size_t(c)]) * t.wt[k];
        const std::int64_t v = (acc + (1 << 19)) >> 20;  // / 1024^2, rounded
        px |= std::uint32_t(std::clamp<std::int64_t>(v, 0, 255)) << (8 * c);
      }
      out[x] = px;
    }
  }
}

void upscale_depth_aware(const std::uint32_t* src, const float* depth, int w, int h, std::uint32_t* dst, int W,
                         int H, float rel_depth) {
  upscale_bilinear(src, w, h, dst, W, H);  // right wherever the four samples agree
  const auto at = [w](int x, int y) { return std::size_t(y) * std::size_t(w) + std::size_t(x); };
  // A 2 x 2 cell (top-left sample x, y) whose samples all missed, or all hit within the
  // tolerance of the nearest of them (and so of any of them), is bilinear's already.
  std::vector<std::uint8_t> mixed(std::size_t(w) * std::size_t(h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int x1 = std::min(x + 1, w - 1), y1 = std::min(y + 1, h - 1);
      const float d[4] = {depth[at(x, y)], depth[at(x1, y)], depth[at(x, y1)], depth[at(x1, y1)]};
      const auto [lo, hi] = std::minmax({d[0], d[1], d[2], d[3]});
      mixed[at(x, y)] = !(hi < 0 || (lo >= 0 && hi - lo <= rel_depth * lo));
    }
  const std::vector<Tap> tx = taps(w, W), ty = taps(h, H);
  for (int y = 0; y < H; ++y) {
    const Tap& r = ty[std::size_t(y)];
    for (int x = 0; x < W; ++x) {
      const Tap& c = tx[std::size_t(x)];
      if (!mixed[at(c.a, r.a)]) continue;
      const std::size_t i[4] = {at(c.a, r.a), at(c.b, r.a), at(c.a, r.b), at(c.b, r.b)};
      const float d[4] = {depth[i[0]], depth[i[1]], depth[i[2]], depth[i[3]]};
      const float near = d[(c.wb >= 128 ? 1 : 0) + (r.wb >= 128 ? 2 : 0)];
      bool keep[4];
      for (int k = 0; k < 4; ++k) keep[k] = near < 0 ? d[k] < 0 : d[k] >= 0 && std::abs(d[k] - near) <= rel_depth * near;
      const std::uint32_t p[4] = {src[i[0]], src[i[1]], src[i[2]], src[i[3]]};
      dst[std::size_t(y) * std::size_t(W) + std::size_t(x)] = blend_kept(p, keep, c.wb, r.wb);
    }
  }
}

}  // namespace isotouch::engine
