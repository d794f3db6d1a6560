#include <algorithm>
#include <limits>
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/parallel.h"

namespace isotouch::engine {

GradientConstants gradient_constants(const core::Grid& g) {
  GradientConstants c{};
  for (int a = 0; a < 3; ++a) {
    c.inv_2h[a] = float(1.0 / (2.0 * g.spacing_m[a]));
    c.inv_h[a] = float(1.0 / g.spacing_m[a]);
  }
  return c;
}

namespace {
// One axis' derivative for a whole row, as (a - b) * k: the rule of diff() in
// shaders/gradient.comp (central inside, one-sided at the borders, 0 on a one-voxel axis)
// decided once per row instead of per voxel. a, b: the rows holding the high and low
// neighbours (the row itself at a border); flat: a one-voxel axis.
struct RowDiff {
  const float* a;
  const float* b;
  float k;
  bool flat;
};
RowDiff row_diff(int i, int n, const float* row, std::size_t stride, float inv_2h, float inv_h) {
  if (n < 2) return {row, row, 0.0f, true};
  if (i == 0) return {row + stride, row, inv_h, false};
  if (i == n - 1) return {row, row - stride, inv_h, false};
  return {row + stride, row - stride, inv_2h, false};
}
}  // namespace

core::SampleField compute_samples_cpu(const Volume& vol, unsigned threads) {
  core::SampleField out;
  out.grid = vol.grid;
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  out.samples.resize(vol.grid.voxel_count());
  const GradientConstants k = gradient_constants(vol.grid);
  const float* f = vol.voxels.data();
  const std::size_t sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);
  // Plain row loops: the y and z rules per row, x's borders outside the interior loop.
  parallel_for(std::size_t(nz), threads, 1, [&](std::size_t z_begin, std::size_t z_end) {
  for (int z = int(z_begin); z < int(z_end); ++z)
    for (int y = 0; y < ny; ++y) {
      const std::size_t base = std::size_t(z) * sz + std::size_t(y) * sy;
      const float* row = f + base;
      core::Sample* o = out.samples.data() + base;
      const RowDiff dy = row_diff(y, ny, row, sy, k.inv_2h[1], k.inv_h[1]);
      const RowDiff dz = row_diff(z, nz, row, sz, k.inv_2h[2], k.inv_h[2]);
      auto put = [&](int x, float gx) {
        const float gy = dy.flat ? 0.0f : (dy.a[x] - dy.b[x]) * dy.k;
        const float gz = dz.flat ? 0.0f : (dz.a[x] - dz.b[x]) * dz.k;
        o[x] = {row[x], gx, gy, gz};
      };
      if (nx < 2) {
        put(0, 0.0f);
        continue;
      }
      put(0, (row[1] - row[0]) * k.inv_h[0]);
      for (int x = 1; x + 1 < nx; ++x) put(x, (row[x + 1] - row[x - 1]) * k.inv_2h[0]);
      put(nx - 1, (row[nx - 1] - row[nx - 2]) * k.inv_h[0]);
    }
  });
  return out;
}

}  // namespace isotouch::engine

#include <cmath>
#include <stdexcept>

namespace isotouch::engine {

GradientDiff compare_gradients(const core::SampleField& a, const core::SampleField& b) {
  if (a.grid.dims != b.grid.dims || a.samples.size() != b.samples.size())
    throw std::invalid_argument("compare_gradients: grids differ");
  GradientDiff d;
  for (std::size_t i = 0; i < a.samples.size(); ++i) {
    const core::Sample& s = a.samples[i];
    const core::Sample& r = b.samples[i];
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
