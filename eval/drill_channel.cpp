#include "isotouch/eval/drill_channel.h"

#include <algorithm>
#include <cmath>

namespace isotouch::eval {
using core::Vec3;

double volume_trilinear(const engine::Volume& v, const Vec3& x_m) {
  const Vec3 i = v.grid.to_index(x_m);
  const auto& d = v.grid.dims;
  auto at = [&](int a, int b, int c) {
    a = std::clamp(a, 0, d[0] - 1), b = std::clamp(b, 0, d[1] - 1), c = std::clamp(c, 0, d[2] - 1);
    return double(v.voxels[v.grid.index(a, b, c)]);
  };
  const int x0 = int(std::floor(i.x)), y0 = int(std::floor(i.y)), z0 = int(std::floor(i.z));
  const double fx = i.x - x0, fy = i.y - y0, fz = i.z - z0;
  double r = 0;
  for (int c = 0; c < 2; ++c)
    for (int b = 0; b < 2; ++b)
      for (int a = 0; a < 2; ++a)
        r += (a ? fx : 1 - fx) * (b ? fy : 1 - fy) * (c ? fz : 1 - fz) * at(x0 + a, y0 + b, z0 + c);
  return r;
}

ChannelFigures measure_channel(const engine::Volume& before, const engine::Volume& after, const core::Isosurface& iso,
                               const std::vector<Vec3>& centres, const Vec3& axis, double burr_radius_m) {
  ChannelFigures f;
  if (centres.empty() || !(burr_radius_m > 0)) return f;
  const Vec3& sp = before.grid.spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  // (u, w): a tangent basis of the slices.
  const Vec3 a = std::abs(axis.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  const Vec3 u = (a - axis * core::dot(a, axis)) / core::norm(a - axis * core::dot(a, axis));
  const Vec3 w = core::cross(axis, u);
  // Depth of each centre along the axis; slices from the shallowest to the deepest.
  double d0 = 1e300, d1 = -1e300;
  for (const Vec3& c : centres) {
    d0 = std::min(d0, core::dot(c, axis));
    d1 = std::max(d1, core::dot(c, axis));
  }
  auto centre_at = [&](double depth) {  // the path's centre nearest that depth
    const Vec3* best = &centres.front();
    double bd = 1e300;
    for (const Vec3& c : centres) {
      const double e = std::abs(core::dot(c, axis) - depth);
      if (e < bd) bd = e, best = &c;
    }
    return *best + axis * (depth - core::dot(*best, axis));
  };
  f.min_open_radius_m = 1e300;
  const double step = 0.25 * voxel, dr = 0.05 * voxel, rmax = 1.5 * burr_radius_m;
  double first = 0;  // depth of the first slice measured
  for (double depth = d0; depth <= d1; depth += step) {
    const Vec3 c = centre_at(depth);
    if (!iso.contains(volume_trilinear(before, c))) continue;  // no material here before: not the channel
    if (f.slices == 0) first = depth;
    double open = 0;
    for (double rho = 0; rho <= rmax; rho += dr) {
      bool clear = true;
      for (int k = 0; k < 24 && clear; ++k) {
        const double ang = k * (2 * M_PI / 24);
        clear = !iso.contains(volume_trilinear(after, c + (u * std::cos(ang) + w * std::sin(ang)) * rho));
      }
      if (!clear) break;
      open = rho;
    }
    ++f.slices;
    if (open < f.min_open_radius_m) {
      f.min_open_radius_m = open;
      f.min_at_depth_m = depth - first;
      f.min_centre_m = c;
    }
  }
  f.measured = f.slices > 0;
  if (!f.measured) f.min_open_radius_m = 0;
  f.min_fraction = f.min_open_radius_m / burr_radius_m;
  return f;
}

Breakthrough find_breakthrough(const std::vector<double>& t_s, const std::vector<double>& force_n,
                               const std::vector<char>& drilling, double threshold_n, double hold_s, double window_s) {
  Breakthrough b;
  const std::size_t n = std::min({t_s.size(), force_n.size(), drilling.size()});
  const double floor_n = 0.1 * threshold_n;
  bool drilled = false;  // |F| was above the threshold while the button was down
  for (std::size_t k = 0; k < n; ++k) {
    if (!drilling[k]) continue;
    if (force_n[k] > threshold_n) drilled = true;
    if (!drilled || force_n[k] > floor_n) continue;
    // Down to the floor: does it stay there for hold_s while the button is down?
    std::size_t j = k;
    while (j < n && drilling[j] && !(force_n[j] > floor_n) && t_s[j] - t_s[k] < hold_s) ++j;
    if (j < n && drilling[j] && force_n[j] > floor_n) continue;
    b.found = true;
    b.t_s = t_s[k];
    b.to_n = force_n[k];
    std::size_t i = k;
    while (i > 0 && t_s[k] - t_s[i - 1] <= window_s) b.from_n = std::max(b.from_n, force_n[--i]);
    std::size_t m = k;
    while (m > 0 && force_n[m - 1] < 0.9 * b.from_n) --m;
    b.fall_s = m > 0 ? t_s[k] - t_s[m - 1] : 0.0;
    return b;
  }
  return b;
}

}  // namespace isotouch::eval
