// Compiled with -ffp-contract=off (engine/CMakeLists.txt): see cpu_filters.h.
#include "cpu_filters.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

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

GaussianAxes gaussian_axes(const servo::Grid& g, double sigma_mm) {
  if (!(std::isfinite(sigma_mm) && sigma_mm > 0))
    throw std::invalid_argument("gaussian: sigma_mm must be finite and > 0, got " + std::to_string(sigma_mm));
  GaussianAxes a;
  for (int i = 0; i < 3; ++i) {
    a.sigma_vox[std::size_t(i)] = sigma_mm / (g.spacing_m[i] * 1e3);
    a.kernel[std::size_t(i)] = gaussian_kernel(a.sigma_vox[std::size_t(i)]);
  }
  return a;
}

std::array<int, 3> closing_radii(const servo::Grid& g, double radius_mm) {
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
// Visits every voxel with its axis coordinate i, the axis length n and the stride along
// the axis; f(out_index, line_base_index, i) where in[line_base + j * stride] is voxel j.
template <class F>
void for_each_line(const servo::Grid& g, int axis, F&& f) {
  const auto [nx, ny, nz] = g.dims;
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const std::size_t o = g.index(x, y, z);
        const int i = axis == 0 ? x : axis == 1 ? y : z;
        const std::size_t base = axis == 0 ? g.index(0, y, z) : axis == 1 ? g.index(x, 0, z) : g.index(x, y, 0);
        f(o, base, i);
      }
}
std::size_t stride_of(const servo::Grid& g, int axis) {
  return axis == 0 ? 1 : axis == 1 ? std::size_t(g.dims[0]) : std::size_t(g.dims[0]) * std::size_t(g.dims[1]);
}
}  // namespace

void gaussian_axis_cpu(const std::vector<float>& in, std::vector<float>& out, const servo::Grid& g, int axis,
                       const std::vector<float>& w) {
  out.resize(in.size());
  const int n = g.dims[std::size_t(axis)];
  const int r = int(w.size() / 2);
  const std::size_t s = stride_of(g, axis);
  for_each_line(g, axis, [&](std::size_t o, std::size_t base, int i) {
    float acc = 0.0f;
    for (int k = -r; k <= r; ++k) {
      const int j = std::clamp(i + k, 0, n - 1);
      const float term = w[std::size_t(k + r)] * in[base + std::size_t(j) * s];
      acc = acc + term;
    }
    out[o] = acc;
  });
}

void morph_axis_cpu(const std::vector<float>& in, std::vector<float>& out, const servo::Grid& g, int axis,
                    int r, bool is_max) {
  out.resize(in.size());
  const int n = g.dims[std::size_t(axis)];
  const std::size_t s = stride_of(g, axis);
  const float start = is_max ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity();
  for_each_line(g, axis, [&](std::size_t o, std::size_t base, int i) {
    float m = start;
    for (int k = -r; k <= r; ++k) {
      const float v = in[base + std::size_t(std::clamp(i + k, 0, n - 1)) * s];
      m = is_max ? (v > m ? v : m) : (v < m ? v : m);
    }
    out[o] = m;
  });
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

BrickRanges brick_minmax_cpu(const Volume& v, int halo) {
  BrickRanges b;
  b.halo = halo;
  const auto [nx, ny, nz] = v.grid.dims;
  for (int a = 0; a < 3; ++a) b.bricks[std::size_t(a)] = (v.grid.dims[std::size_t(a)] + 7) / 8;
  const std::size_t count = std::size_t(b.bricks[0]) * std::size_t(b.bricks[1]) * std::size_t(b.bricks[2]);
  b.min.assign(count, 0.0f);
  b.max.assign(count, 0.0f);
  const float inf = std::numeric_limits<float>::infinity();
  std::size_t o = 0;
  for (int bz = 0; bz < b.bricks[2]; ++bz)
    for (int by = 0; by < b.bricks[1]; ++by)
      for (int bx = 0; bx < b.bricks[0]; ++bx, ++o) {
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
  return b;
}

}  // namespace isotouch::engine
