// Compiled with -ffp-contract=off (engine/CMakeLists.txt): see cpu_filters.h.
#include "isotouch/engine/cpu_filters.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "isotouch/engine/parallel.h"

namespace isotouch::engine {

std::vector<float> gaussian_kernel(double sigma_vox) {
  if (!std::isfinite(sigma_vox)) throw std::invalid_argument("gaussian_kernel: sigma is not finite");
  if (sigma_vox <= 0) return {1.0f};
  const double rr = std::ceil(3.0 * sigma_vox);
  if (rr > kMaxFilterRadius)
    throw std::invalid_argument("gaussian: radius ceil(3 sigma) = " + std::to_string(int(rr)) +
                                " voxels exceeds " + std::to_string(kMaxFilterRadius) +
                                " (sigma " + std::to_string(sigma_vox) + " voxels)");
  const int r = int(rr);
  std::vector<double> e(std::size_t(2 * r + 1));
  double sum = 0;
  for (int k = -r; k <= r; ++k) sum += e[std::size_t(k + r)] = std::exp(-double(k) * k / (2 * sigma_vox * sigma_vox));
  std::vector<float> w(e.size());
  for (std::size_t i = 0; i < e.size(); ++i) w[i] = float(e[i] / sum);
  return w;
}

GaussianAxes gaussian_axes(const core::Grid& g, double sigma_mm) {
  if (!(std::isfinite(sigma_mm) && sigma_mm > 0))
    throw std::invalid_argument("gaussian: sigma_mm must be finite and > 0, got " + std::to_string(sigma_mm));
  GaussianAxes a;
  for (int i = 0; i < 3; ++i) {
    a.sigma_vox[std::size_t(i)] = sigma_mm / (g.spacing_m[i] * 1e3);
    a.kernel[std::size_t(i)] = gaussian_kernel(a.sigma_vox[std::size_t(i)]);
  }
  return a;
}

std::array<int, 3> closing_radii(const core::Grid& g, double radius_mm) {
  if (!(std::isfinite(radius_mm) && radius_mm >= 0))
    throw std::invalid_argument("closing: radius_mm must be finite and >= 0, got " + std::to_string(radius_mm));
  std::array<int, 3> r{};
  for (int i = 0; i < 3; ++i) {
    const double v = std::floor(radius_mm / (g.spacing_m[i] * 1e3) + 1e-9);
    if (v > kMaxFilterRadius)
      throw std::invalid_argument("closing: radius " + std::to_string(radius_mm) + " mm is " + std::to_string(v) +
                                  " voxels along axis " + std::to_string(i) + ", more than " +
                                  std::to_string(kMaxFilterRadius));
    r[std::size_t(i)] = int(v);
  }
  return r;
}

namespace {
std::size_t stride_of(const core::Grid& g, int axis) {
  return axis == 0 ? 1 : axis == 1 ? std::size_t(g.dims[0]) : std::size_t(g.dims[0]) * std::size_t(g.dims[1]);
}

// One axis of a separable filter written as plain row loops; per output voxel the taps are
// combined from k = -r up with `op(acc, k, value)`, starting from `start`, so every voxel
// sees the operations of the per-voxel formula in the same order.
// x: per row, the interior x in [r, nx - r) reads row[x - r + k] without a clamp; the
// border voxels clamp. y and z: per output row, each tap's source row (clamped once per
// row) is combined into the whole row, x innermost.
// `threads`: the slices split in contiguous parts, one thread each (every output row is
// computed by one thread as above: the same bits for any count).
template <class Op>
void filter_axis(const std::vector<float>& in, std::vector<float>& out, const core::Grid& g, int axis, int r,
                 float start, Op op, unsigned threads) {
  out.resize(in.size());
  const int nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];  // not a structured binding: clang 14 cannot capture one
  const std::size_t sx = std::size_t(nx), slice = sx * std::size_t(ny);
  parallel_for(std::size_t(nz), threads, 1, [&](std::size_t z_begin, std::size_t z_end) {
  for (int z = int(z_begin); z < int(z_end); ++z)
    for (int y = 0; y < ny; ++y) {
      const std::size_t base = std::size_t(z) * slice + std::size_t(y) * sx;
      float* o = out.data() + base;
      if (axis == 0) {
        const float* row = in.data() + base;
        auto clamped = [&](int x) {
          float acc = start;
          for (int k = -r; k <= r; ++k) acc = op(acc, k + r, row[std::clamp(x + k, 0, nx - 1)]);
          o[x] = acc;
        };
        const int lo = std::min(r, nx), hi = std::max(lo, nx - r);
        for (int x = 0; x < lo; ++x) clamped(x);
        for (int x = lo; x < hi; ++x) {
          const float* w = row + (x - r);
          float acc = start;
          for (int k = 0; k <= 2 * r; ++k) acc = op(acc, k, w[k]);
          o[x] = acc;
        }
        for (int x = hi; x < nx; ++x) clamped(x);
      } else {
        const int n = axis == 1 ? ny : nz, i = axis == 1 ? y : z;
        const std::size_t s = stride_of(g, axis);
        const float* line = in.data() + base - std::size_t(i) * s;  // voxel j of this column: line[j * s + x]
        std::fill(o, o + nx, start);
        for (int k = -r; k <= r; ++k) {
          const float* src = line + std::size_t(std::clamp(i + k, 0, n - 1)) * s;
          for (int x = 0; x < nx; ++x) o[x] = op(o[x], k + r, src[x]);
        }
      }
    }
  });
}
}  // namespace

void gaussian_axis_cpu(const std::vector<float>& in, std::vector<float>& out, const core::Grid& g, int axis,
                       const std::vector<float>& w, unsigned threads) {
  const float* wk = w.data();
  filter_axis(
      in, out, g, axis, int(w.size() / 2), 0.0f,
      [wk](float acc, int k, float v) {
        const float term = wk[k] * v;
        return acc + term;
      },
      threads);
}

void morph_axis_cpu(const std::vector<float>& in, std::vector<float>& out, const core::Grid& g, int axis,
                    int r, bool is_max, unsigned threads) {
  const float start = is_max ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity();
  if (is_max)
    filter_axis(in, out, g, axis, r, start, [](float m, int, float v) { return v > m ? v : m; }, threads);
  else
    filter_axis(in, out, g, axis, r, start, [](float m, int, float v) { return v < m ? v : m; }, threads);
}

Volume gaussian_cpu(const Volume& v, double sigma_mm) {
  const GaussianAxes a = gaussian_axes(v.grid, sigma_mm);
  Volume out = v;
  std::vector<float> tmp;
  for (int axis = 0; axis < 3; ++axis) {
    gaussian_axis_cpu(out.voxels, tmp, v.grid, axis, a.kernel[std::size_t(axis)]);
    out.voxels.swap(tmp);
  }
  out.update_stats();
  return out;
}

Volume closing_cpu(const Volume& v, double radius_mm) {
  const auto r = closing_radii(v.grid, radius_mm);
  Volume out = v;
  std::vector<float> tmp;
  for (int pass = 0; pass < 6; ++pass) {
    const int axis = pass % 3;
    morph_axis_cpu(out.voxels, tmp, v.grid, axis, r[std::size_t(axis)], pass < 3);
    out.voxels.swap(tmp);
  }
  out.update_stats();
  return out;
}

BrickRanges brick_minmax_cpu(const Volume& v, int halo, unsigned threads) {
  BrickRanges b;
  b.halo = halo;
  const int nx = v.grid.dims[0], ny = v.grid.dims[1], nz = v.grid.dims[2];
  for (int a = 0; a < 3; ++a) b.bricks[std::size_t(a)] = (v.grid.dims[std::size_t(a)] + 7) / 8;
  const std::size_t count = std::size_t(b.bricks[0]) * std::size_t(b.bricks[1]) * std::size_t(b.bricks[2]);
  b.min.assign(count, 0.0f);
  b.max.assign(count, 0.0f);
  const float inf = std::numeric_limits<float>::infinity();
  parallel_for(std::size_t(b.bricks[2]), threads, 1, [&](std::size_t bz_begin, std::size_t bz_end) {
  for (int bz = int(bz_begin); bz < int(bz_end); ++bz)
    for (int by = 0; by < b.bricks[1]; ++by)
      for (int bx = 0; bx < b.bricks[0]; ++bx) {
        const std::size_t o = (std::size_t(bz) * std::size_t(b.bricks[1]) + std::size_t(by)) * std::size_t(b.bricks[0]) +
                              std::size_t(bx);
        const int x0 = std::max(bx * 8 - halo, 0), x1 = std::min(bx * 8 + 8 + halo, nx);
        const int y0 = std::max(by * 8 - halo, 0), y1 = std::min(by * 8 + 8 + halo, ny);
        const int z0 = std::max(bz * 8 - halo, 0), z1 = std::min(bz * 8 + 8 + halo, nz);
        float mn = inf, mx = -inf;
        for (int z = z0; z < z1; ++z)
          for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x) {
              const float val = v.voxels[v.grid.index(x, y, z)];
              mn = val < mn ? val : mn;
              mx = val > mx ? val : mx;
            }
        b.min[o] = mn;
        b.max[o] = mx;
      }
  });
  return b;
}

}  // namespace isotouch::engine
