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

namespace {
// One axis of a clamp-to-edge lookup: element offset of the lower corner, offset to the
// upper corner (0 on a 1-voxel axis) and the fraction; false if not finite.
struct AxisCell {
  std::size_t off, step;
  double f;
};
inline bool axis_cell(double v, int n, std::size_t stride, AxisCell& c) {
  if (!std::isfinite(v)) return false;
  const double cl = std::clamp(v, 0.0, double(n - 1));
  int i0 = int(cl);
  if (i0 >= n - 1) i0 = std::max(n - 2, 0);
  c.f = n > 1 ? cl - i0 : 0.0;
  c.step = n > 1 ? stride : 0;
  c.off = std::size_t(i0) * stride;
  return true;
}
inline double trilerp(const Sample* base, const AxisCell& x, const AxisCell& y, const AxisCell& z) {
  const Sample* s = base + x.off + y.off + z.off;
  const std::size_t sx = x.step, sy = y.step, sz = z.step;
  auto lerp = [](double a, double b, double t) { return a + t * (b - a); };
  const double c00 = lerp(s[0].value, s[sx].value, x.f);
  const double c10 = lerp(s[sy].value, s[sy + sx].value, x.f);
  const double c01 = lerp(s[sz].value, s[sz + sx].value, x.f);
  const double c11 = lerp(s[sz + sy].value, s[sz + sy + sx].value, x.f);
  return lerp(lerp(c00, c10, y.f), lerp(c01, c11, y.f), z.f);
}
}  // namespace

double sample_value(const SampleField& field, const Vec3& world_m) {
  // The servo's hot path (HRI reads values only): strides instead of index() per
  // corner, and seven lerps. Same clamp-to-edge rules as locate().
  const Grid& g = field.grid;
  if (g.dims[0] <= 0 || g.dims[1] <= 0 || g.dims[2] <= 0) return std::numeric_limits<double>::quiet_NaN();
  const Vec3 idx = g.to_index(world_m);
  AxisCell c[3];
  std::size_t stride = 1;
  for (int a = 0; a < 3; ++a) {
    if (!axis_cell(idx[a], g.dims[a], stride, c[a])) return std::numeric_limits<double>::quiet_NaN();
    stride *= std::size_t(g.dims[a]);
  }
  return trilerp(field.samples.data(), c[0], c[1], c[2]);
}

Vec3 central_difference_gradient(const SampleField& field, const Vec3& world_m, const Vec3& h_m) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Grid& g = field.grid;
  if (g.dims[0] <= 0 || g.dims[1] <= 0 || g.dims[2] <= 0) return {nan, nan, nan};
  const Vec3 idx = g.to_index(world_m);
  const Vec3 hi{h_m.x / g.spacing_m.x, h_m.y / g.spacing_m.y, h_m.z / g.spacing_m.z};  // [voxels]
  AxisCell c[3][3];  // [axis][minus, centre, plus]
  std::size_t stride = 1;
  for (int a = 0; a < 3; ++a) {
    const int n = g.dims[a];
    if (!axis_cell(idx[a] - hi[a], n, stride, c[a][0]) || !axis_cell(idx[a], n, stride, c[a][1]) ||
        !axis_cell(idx[a] + hi[a], n, stride, c[a][2]))
      return {nan, nan, nan};
    stride *= std::size_t(n);
  }
  const Sample* s = field.samples.data();
  return {(trilerp(s, c[0][2], c[1][1], c[2][1]) - trilerp(s, c[0][0], c[1][1], c[2][1])) / (2 * h_m.x),
          (trilerp(s, c[0][1], c[1][2], c[2][1]) - trilerp(s, c[0][1], c[1][0], c[2][1])) / (2 * h_m.y),
          (trilerp(s, c[0][1], c[1][1], c[2][2]) - trilerp(s, c[0][1], c[1][1], c[2][0])) / (2 * h_m.z)};
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
