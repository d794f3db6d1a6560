#include "isotouch/materials/critical_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "isotouch/materials/material.h"

namespace isotouch::materials {
namespace {
constexpr double kFar = 1e30;  // squared distance of "no site" (finite: the envelope's arithmetic stays exact)

/// One line of the squared transform: d[i] = min_j f[j] + ((i - j) s)^2 (Felzenszwalb &
/// Huttenlocher 2012), n samples `stride` apart in f and d, spacing s [m].
void envelope_1d(double* line, int n, std::size_t stride, double s, std::vector<double>& f, std::vector<int>& v,
                 std::vector<double>& z) {
  f.resize(std::size_t(n));
  v.resize(std::size_t(n));
  z.resize(std::size_t(n) + 1);
  for (int i = 0; i < n; ++i) f[std::size_t(i)] = line[std::size_t(i) * stride];
  const auto key = [&](int q) { return f[std::size_t(q)] + (q * s) * (q * s); };
  int k = 0;
  v[0] = 0;
  z[0] = -std::numeric_limits<double>::infinity();
  z[1] = std::numeric_limits<double>::infinity();
  for (int q = 1; q < n; ++q) {
    double x = (key(q) - key(v[std::size_t(k)])) / (2 * s * s * (q - v[std::size_t(k)]));
    while (x <= z[std::size_t(k)]) {
      --k;
      x = (key(q) - key(v[std::size_t(k)])) / (2 * s * s * (q - v[std::size_t(k)]));
    }
    ++k;
    v[std::size_t(k)] = q;
    z[std::size_t(k)] = x;
    z[std::size_t(k) + 1] = std::numeric_limits<double>::infinity();
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[std::size_t(k) + 1] < q) ++k;
    const double dq = (q - v[std::size_t(k)]) * s;
    line[std::size_t(q) * stride] = dq * dq + f[std::size_t(v[std::size_t(k)])];
  }
}
}  // namespace

CriticalDistance::CriticalDistance(const core::Grid& grid, const std::vector<std::uint8_t>& ids,
                                   const std::vector<bool>& critical)
    : grid_(grid) {
  const std::size_t n = grid.voxel_count();
  if (ids.size() != n)
    throw MaterialError("critical distance: " + std::to_string(ids.size()) + " labels for a grid of " +
                        std::to_string(n) + " voxels");
  std::vector<double> sq(n);
  for (std::size_t i = 0; i < n; ++i) {
    const bool c = ids[i] < critical.size() && critical[ids[i]];
    any_ = any_ || c;
    sq[i] = c ? 0.0 : kFar;
  }
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const std::size_t sx = 1, sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);
  std::vector<double> f, z;
  std::vector<int> v;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j) envelope_1d(&sq[k * sz + j * sy], nx, sx, grid.spacing_m.x, f, v, z);
  for (int k = 0; k < nz; ++k)
    for (int i = 0; i < nx; ++i) envelope_1d(&sq[k * sz + std::size_t(i)], ny, sy, grid.spacing_m.y, f, v, z);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) envelope_1d(&sq[j * sy + std::size_t(i)], nz, sz, grid.spacing_m.z, f, v, z);
  d_.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    d_[i] = sq[i] >= kFar * 0.5 ? std::numeric_limits<float>::infinity() : float(std::sqrt(sq[i]));
}

double CriticalDistance::lower_bound(const core::Vec3& p) const {
  if (!any_) return std::numeric_limits<double>::infinity();
  const core::Vec3 c = grid_.to_index(p);
  const double ci[3] = {c.x, c.y, c.z};
  const double s[3] = {grid_.spacing_m.x, grid_.spacing_m.y, grid_.spacing_m.z};
  int lo[3];
  double box2 = 0;  // squared distance from p to the grid's box of voxel centres [m^2]
  for (int a = 0; a < 3; ++a) {
    const double cl = std::clamp(ci[a], 0.0, double(grid_.dims[a] - 1));
    box2 += ((ci[a] - cl) * s[a]) * ((ci[a] - cl) * s[a]);
    lo[a] = std::min(int(std::floor(cl)), std::max(grid_.dims[a] - 2, 0));
  }
  double best = std::sqrt(box2);
  for (int corner = 0; corner < 8; ++corner) {
    int q[3];
    double e2 = 0;
    for (int a = 0; a < 3; ++a) {
      q[a] = std::min(lo[a] + ((corner >> a) & 1), grid_.dims[a] - 1);
      e2 += ((ci[a] - q[a]) * s[a]) * ((ci[a] - q[a]) * s[a]);
    }
    best = std::max(best, at(q[0], q[1], q[2]) - std::sqrt(e2));
  }
  return best;
}

}  // namespace isotouch::materials
