// thin_ridges.h - test helper: a property-test generator of scan-like thin features for the
// thin-feature wrap check (thin_features.h). Ridges (a plate with a free crest) and long
// cylinders 2-4 voxels thick, tilted 20-45 deg from the grid axes, with partial-volume edges
// (the shape's indicator blurred by a Gaussian point-spread function, as a scanner images it),
// noise of a few percent of the contrast on every sample, gradients by central differences
// of the noisy samples (as the pipeline computes them), on 1 mm and up to 1 x 1 x 3 mm voxels.
// Truth from the analytic shape: the feature's middle and the entry normal.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/tests/thin_features.h"

namespace isotouch::test {

/// Standard normal cumulative distribution.
inline double phi(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

/// The voxel size seen along unit direction m [m] (the spacings weighted by m's squares).
inline double voxel_along(const Vec3& m, const Vec3& sp) { return m.x * m.x * sp.x + m.y * m.y * sp.y + m.z * m.z * sp.z; }

/// A field of `dims` voxels of spacing `sp` [m]: value(p) [contrast units, tau = 0 at half
/// contrast, positive inside] plus Gaussian noise of `noise` [same units] on every sample
/// (seeded by `seed`), gradient samples [units/m] by central differences of the noisy values
/// (one-sided at the border).
inline SampleField scan_like_field(std::array<int, 3> dims, Vec3 sp, const std::function<double(const Vec3&)>& value,
                                   double noise, unsigned seed) {
  SampleField f;
  f.grid.dims = dims;
  f.grid.spacing_m = sp;
  f.grid.origin_m = {0, 0, 0};
  f.samples.resize(f.grid.voxel_count());
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0.0, noise);
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x)
        f.samples[f.grid.index(x, y, z)].value = float(value(f.grid.to_world({double(x), double(y), double(z)})) + gauss(rng));
  auto v = [&](int x, int y, int z) { return double(f.samples[f.grid.index(x, y, z)].value); };
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        const int x0 = std::max(x - 1, 0), x1 = std::min(x + 1, dims[0] - 1);
        const int y0 = std::max(y - 1, 0), y1 = std::min(y + 1, dims[1] - 1);
        const int z0 = std::max(z - 1, 0), z1 = std::min(z + 1, dims[2] - 1);
        core::Sample& s = f.samples[f.grid.index(x, y, z)];
        s.gx = float((v(x1, y, z) - v(x0, y, z)) / ((x1 - x0) * sp.x));
        s.gy = float((v(x, y1, z) - v(x, y0, z)) / ((y1 - y0) * sp.y));
        s.gz = float((v(x, y, z1) - v(x, y, z0)) / ((z1 - z0) * sp.z));
      }
  return f;
}

/// One drawn case: what it is (for the message) and the feature.
struct RidgeCase {
  std::string name;
  ThinCase thin;
};

/// Unit vector tilted `tilt` [rad] from axis `a` toward `b` (both unit, perpendicular).
inline Vec3 tilted(const Vec3& a, const Vec3& b, double tilt) { return a * std::cos(tilt) + b * std::sin(tilt); }

/// A ridge: the plate |m.(x - c)| < w/2 on the side t.(x - c) < 0 of its crest (t
/// perpendicular to m), imaged with a Gaussian PSF of width sigma [m] (separable: the plate's
/// profile across m times the crest's along t), contrast 1000; pressed on its face 1.5
/// voxels in from the crest, stroked along the crest and across it (over the crest).
inline ThinFeature ridge(Vec3 m, Vec3 t, double w, Vec3 sp, double sigma, double noise, unsigned seed) {
  const Vec3 c{0.024, 0.024, 0.036};
  const std::array<int, 3> dims{int(0.048 / sp.x) + 1, int(0.048 / sp.y) + 1, int(0.072 / sp.z) + 1};
  const double edge_in = 1.5 * voxel_along(t, sp);
  ThinFeature tf;
  tf.field = scan_like_field(
      dims, sp,
      [=](const Vec3& x) {
        const double u = dot(m, x - c), v = dot(t, x - c);
        const double across = phi((u + 0.5 * w) / sigma) - phi((u - 0.5 * w) / sigma);
        return 1000.0 * (across * phi(-v / sigma) - 0.5);
      },
      noise, seed);
  plate_frame(tf, c, m, t, w, edge_in);
  return tf;
}

/// A long cylinder of radius R along unit a (no end in the box), imaged with a Gaussian PSF
/// of width sigma [m] (the radial profile Phi((R - r) / sigma), contrast 1000); pressed from
/// unit n (perpendicular to a), stroked along the axis and across it (over the crest).
inline ThinFeature cylinder(Vec3 a, Vec3 n, double radius, Vec3 sp, double sigma, double noise, unsigned seed) {
  const Vec3 c{0.024, 0.024, 0.036};
  const std::array<int, 3> dims{int(0.048 / sp.x) + 1, int(0.048 / sp.y) + 1, int(0.072 / sp.z) + 1};
  ThinFeature tf;
  tf.field = scan_like_field(
      dims, sp,
      [=](const Vec3& x) {
        const Vec3 r = (x - c) - a * dot(a, x - c);
        return 1000.0 * (phi((radius - norm(r)) / sigma) - 0.5);
      },
      noise, seed);
  tf.mid = c;
  tf.n_entry = n;
  tf.half = radius;
  tf.along = a;
  tf.across = cross(n, a);
  tf.along_len = 0.012;
  tf.across_len = radius + 0.004;
  return tf;
}

/// `count` cases drawn from `seed`: ridges and cylinders alternately, 2-4 voxels thick (along
/// the press), tilted 20-45 deg from a grid axis about a random azimuth, on 1 x 1 x s mm
/// voxels (s in {1, 2, 3}), PSF sigma 0.3-0.6 voxel, noise 1-4 % of the contrast.
inline std::vector<RidgeCase> ridge_cases(unsigned seed, int count) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<RidgeCase> cases;
  auto unit = [](Vec3 v) { return v / norm(v); };
  for (int i = 0; i < count; ++i) {
    const double tilt = (20.0 + 25.0 * uni(rng)) * M_PI / 180.0, az = 2.0 * M_PI * uni(rng);
    const int voxels = 2 + int(3.0 * uni(rng)) % 3;
    const double sz = 1.0 + double(int(3.0 * uni(rng)) % 3);
    const Vec3 sp{1e-3, 1e-3, sz * 1e-3};
    const double sigma_vox = 0.3 + 0.3 * uni(rng), noise = 10.0 + 30.0 * uni(rng);  // of 1000
    const int axis = int(3.0 * uni(rng)) % 3;
    const Vec3 e[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    const Vec3 ax = e[axis], b1 = e[(axis + 1) % 3], b2 = e[(axis + 2) % 3];
    const Vec3 off = unit(b1 * std::cos(az) + b2 * std::sin(az));  // the tilt's direction
    const Vec3 m = tilted(ax, off, tilt);                            // press normal / plate normal
    const Vec3 t = unit(off - m * dot(off, m));  // perpendicular to m, tilted as far from the grid plane
    char name[160];
    const double vox = voxel_along(m, sp);
    const double sigma = sigma_vox * vox;
    ThinFeature tf;
    if (i % 2 == 0) {
      tf = ridge(m, t, voxels * vox, sp, sigma, noise, seed * 131u + unsigned(i));
      std::snprintf(name, sizeof name, "ridge #%d, normal %.0f deg off axis %d, 1x1x%.0f mm, psf %.2f vox, noise %.1f %%",
                    i, tilt * 180 / M_PI, axis, sz, sigma_vox, noise / 10);
    } else {
      tf = cylinder(t, m, 0.5 * voxels * vox, sp, sigma, noise, seed * 131u + unsigned(i));
      std::snprintf(name, sizeof name,
                    "cylinder #%d, press normal %.0f deg off axis %d, 1x1x%.0f mm, psf %.2f vox, noise %.1f %%", i,
                    tilt * 180 / M_PI, axis, sz, sigma_vox, noise / 10);
    }
    tf.scan_like = true;
    cases.push_back({name, ThinCase{"", voxels, std::move(tf)}});
  }
  return cases;
}

}  // namespace isotouch::test
