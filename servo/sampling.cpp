#include "sampling.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace isotouch::servo {
namespace {

struct Cell {
  int i0[3];
  int i1[3];
  double f[3];  // fractional position in the cell
};

// Clamp-to-edge cell lookup. Returns false on an empty grid or non-finite input.
bool locate(const Grid& g, const Vec3& world_m, Cell& c) {
  if (g.dims[0] <= 0 || g.dims[1] <= 0 || g.dims[2] <= 0) return false;
  const Vec3 idx = g.to_index(world_m);
  for (int a = 0; a < 3; ++a) {
    const double v = idx[a];
    if (!std::isfinite(v)) return false;
    const int n = g.dims[a];
    const double cl = std::clamp(v, 0.0, double(n - 1));
    int i0 = int(std::floor(cl));
    if (i0 >= n - 1) i0 = std::max(n - 2, 0);
    c.i0[a] = i0;
    c.i1[a] = std::min(i0 + 1, n - 1);
    c.f[a] = n > 1 ? cl - i0 : 0.0;
  }
  return true;
}

}  // namespace

FieldValue sample_trilinear(const SampleField& field, const Vec3& world_m) {
  FieldValue out;
  Cell c;
  if (!locate(field.grid, world_m, c)) {
    out.value = std::numeric_limits<double>::quiet_NaN();
    return out;
  }
  const Grid& g = field.grid;
  double v = 0, gx = 0, gy = 0, gz = 0;
  for (int k = 0; k < 2; ++k) {
    const double wz = k ? c.f[2] : 1.0 - c.f[2];
    const int z = k ? c.i1[2] : c.i0[2];
    for (int j = 0; j < 2; ++j) {
      const double wy = j ? c.f[1] : 1.0 - c.f[1];
      const int y = j ? c.i1[1] : c.i0[1];
      for (int i = 0; i < 2; ++i) {
        const double w = (i ? c.f[0] : 1.0 - c.f[0]) * wy * wz;
        const Sample& s = field.samples[g.index(i ? c.i1[0] : c.i0[0], y, z)];
        v += w * s.value;
        gx += w * s.gx;
        gy += w * s.gy;
        gz += w * s.gz;
      }
    }
  }
  out.value = v;
  out.gradient = {gx, gy, gz};
  return out;
}

double sample_value(const SampleField& field, const Vec3& world_m) {
  Cell c;
  if (!locate(field.grid, world_m, c)) return std::numeric_limits<double>::quiet_NaN();
  const Grid& g = field.grid;
  double v = 0;
  for (int k = 0; k < 2; ++k) {
    const double wz = k ? c.f[2] : 1.0 - c.f[2];
    for (int j = 0; j < 2; ++j) {
      const double wy = j ? c.f[1] : 1.0 - c.f[1];
      for (int i = 0; i < 2; ++i) {
        const double w = (i ? c.f[0] : 1.0 - c.f[0]) * wy * wz;
        v += w * field.samples[g.index(i ? c.i1[0] : c.i0[0], j ? c.i1[1] : c.i0[1],
                                       k ? c.i1[2] : c.i0[2])]
                     .value;
      }
    }
  }
  return v;
}

Vec3 trilinear_field_gradient(const SampleField& field, const Vec3& world_m) {
  Cell c;
  if (!locate(field.grid, world_m, c)) return {};
  const Grid& g = field.grid;
  auto val = [&](int i, int j, int k) {
    return double(field.samples[g.index(i ? c.i1[0] : c.i0[0], j ? c.i1[1] : c.i0[1],
                                        k ? c.i1[2] : c.i0[2])]
                      .value);
  };
  double d[3] = {0, 0, 0};
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const double v = val(i, j, k);
        const double wx = i ? c.f[0] : 1 - c.f[0], wy = j ? c.f[1] : 1 - c.f[1],
                     wz = k ? c.f[2] : 1 - c.f[2];
        const double sx = i ? 1.0 : -1.0, sy = j ? 1.0 : -1.0, sz = k ? 1.0 : -1.0;
        d[0] += sx * wy * wz * v;
        d[1] += wx * sy * wz * v;
        d[2] += wx * wy * sz * v;
      }
  return {d[0] / g.spacing_m.x, d[1] / g.spacing_m.y, d[2] / g.spacing_m.z};
}

}  // namespace isotouch::servo
