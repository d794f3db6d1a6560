#include "isotouch/sim/analytic_fields.h"

#include <cmath>

namespace isotouch::sim {
namespace {
template <class F>
SampleField make(int dims, double h, F&& f) {
  SampleField s;
  s.grid.dims = {dims, dims, dims};
  s.grid.spacing_m = {h, h, h};
  s.samples.resize(s.grid.voxel_count());
  for (int z = 0; z < dims; ++z)
    for (int y = 0; y < dims; ++y)
      for (int x = 0; x < dims; ++x) {
        Vec3 g;
        const double v = f(s.grid.to_world({double(x), double(y), double(z)}), g);
        s.samples[s.grid.index(x, y, z)] = {float(v), float(g.x), float(g.y), float(g.z)};
      }
  return s;
}
}  // namespace

SampleField plane_field(Vec3 n, Vec3 c, int dims, double h) {
  n = normalized_or(n, {0, 0, 1});
  return make(dims, h, [&](const Vec3& p, Vec3& g) {
    g = n * -1000.0;
    return 1000.0 * dot(n, c - p);
  });
}

SampleField sphere_field(Vec3 c, double r, int dims, double h) {
  return make(dims, h, [&](const Vec3& p, Vec3& g) {
    const Vec3 u = normalized_or(p - c, {0, 0, 1});
    g = u * -1000.0;
    return 1000.0 * (r - norm(p - c));
  });
}

SampleField shell_field(Vec3 c, double r, double t, int dims, double h) {
  return make(dims, h, [&](const Vec3& p, Vec3& g) {
    const Vec3 u = normalized_or(p - c, {0, 0, 1});
    const double dr = norm(p - c) - r;
    g = u * (dr > 0 ? -1000.0 : 1000.0);
    return 1000.0 * (0.5 * t - std::abs(dr));
  });
}

}  // namespace isotouch::sim
