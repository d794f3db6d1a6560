#include <algorithm>
#include <limits>
#include "cpu_gradient.h"

namespace isotouch::engine {

GradientConstants gradient_constants(const servo::Grid& g) {
  GradientConstants c{};
  for (int a = 0; a < 3; ++a) {
    c.inv_2h[a] = float(1.0 / (2.0 * g.spacing_m[a]));
    c.inv_h[a] = float(1.0 / g.spacing_m[a]);
  }
  return c;
}

namespace {
// Mirrors diff() in shaders/gradient.comp operation for operation.
inline float diff(int i, int n, float lo, float c, float hi, float inv_2h, float inv_h) {
  if (n < 2) return 0.0f;
  if (i == 0) return (hi - c) * inv_h;
  if (i == n - 1) return (c - lo) * inv_h;
  return (hi - lo) * inv_2h;
}
}  // namespace

servo::SampleField compute_samples_cpu(const Volume& vol) {
  servo::SampleField out;
  out.grid = vol.grid;
  const auto [nx, ny, nz] = vol.grid.dims;
  out.samples.resize(vol.grid.voxel_count());
  const GradientConstants k = gradient_constants(vol.grid);
  const float* f = vol.voxels.data();
  const std::size_t sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const std::size_t i = vol.grid.index(x, y, z);
        const float c = f[i];
        const float xl = x > 0 ? f[i - 1] : c, xh = x + 1 < nx ? f[i + 1] : c;
        const float yl = y > 0 ? f[i - sy] : c, yh = y + 1 < ny ? f[i + sy] : c;
        const float zl = z > 0 ? f[i - sz] : c, zh = z + 1 < nz ? f[i + sz] : c;
        out.samples[i] = {c, diff(x, nx, xl, c, xh, k.inv_2h[0], k.inv_h[0]),
                          diff(y, ny, yl, c, yh, k.inv_2h[1], k.inv_h[1]),
                          diff(z, nz, zl, c, zh, k.inv_2h[2], k.inv_h[2])};
      }
  return out;
}

}  // namespace isotouch::engine

#include <cmath>
#include <stdexcept>

namespace isotouch::engine {

GradientDiff compare_gradients(const servo::SampleField& a, const servo::SampleField& b) {
  if (a.grid.dims != b.grid.dims || a.samples.size() != b.samples.size())
    throw std::invalid_argument("compare_gradients: grids differ");
  GradientDiff d;
  for (std::size_t i = 0; i < a.samples.size(); ++i) {
    const servo::Sample& s = a.samples[i];
    const servo::Sample& r = b.samples[i];
    const double da[3] = {std::abs(double(s.gx) - r.gx), std::abs(double(s.gy) - r.gy),
                          std::abs(double(s.gz) - r.gz)};
    const double gn = std::sqrt(double(r.gx) * r.gx + double(r.gy) * r.gy + double(r.gz) * r.gz);
    const double dv = std::abs(double(s.value) - r.value);
    if (!(std::isfinite(da[0]) && std::isfinite(da[1]) && std::isfinite(da[2]) &&
          std::isfinite(dv))) {
      // Both NaN at the same place (NaN voxels) is agreement; anything else is not.
      const bool same = std::isnan(s.gx) == std::isnan(r.gx) && std::isnan(s.gy) == std::isnan(r.gy) &&
                        std::isnan(s.gz) == std::isnan(r.gz) && std::isnan(s.value) == std::isnan(r.value);
      if (!same) ++d.nonfinite;
      continue;
    }
    for (int k = 0; k < 3; ++k) d.max_abs[k] = std::max(d.max_abs[k], da[k]);
    d.max_value_abs = std::max(d.max_value_abs, dv);
    d.max_gradient_norm = std::max(d.max_gradient_norm, gn);
  }
  d.max_abs_all = std::max({d.max_abs[0], d.max_abs[1], d.max_abs[2]});
  d.max_rel = d.max_gradient_norm > 0 ? d.max_abs_all / d.max_gradient_norm : d.max_abs_all;
  if (d.nonfinite) d.max_rel = std::numeric_limits<double>::infinity();
  return d;
}

}  // namespace isotouch::engine
