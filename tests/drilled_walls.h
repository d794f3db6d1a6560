// drilled_walls.h - test helper: scan-like thin walls drilled through by the HRI servo's
// probe (a point or a burr) and the lift after the breakthrough. A wall 1-3 voxels thick,
// tilted or across the coarse axis of 1 x 1 x 3 mm voxels, imaged with a Gaussian
// point-spread function (partial-volume edges) and stored as 8-bit or 16-bit integers; the
// drill removes a ball round the tool's centre every edit period while the probe presses, a
// new snapshot each time, as the sculpting session publishes them. Truth from the analytic
// wall: its normal, along which the probe is lifted.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/servo/hri.h"
#include "isotouch/tests/thin_ridges.h"

namespace isotouch::test {

/// One wall: normal m (unit, the side pressed), thickness w [m], voxel spacing [m], PSF
/// sigma [m], the stored integer range (255: 8-bit, 4095: 16-bit CT-like).
struct WallCase {
  std::string name;
  Vec3 m, sp;
  double w = 0, sigma = 0, full = 255;
  double noise = 0;                    ///< noise on every voxel, a fraction of `full` (std dev)
  Vec3 box{0.024, 0.024, 0.036};       ///< the volume's extent [m]
};

/// The walls: 1-3 voxels thick along m, on 1 mm voxels (tilted 30 deg) and 1 x 1 x 3 mm
/// voxels (across z, the coarse axis), 8-bit and 16-bit.
inline std::vector<WallCase> wall_cases() {
  std::vector<WallCase> cases;
  const Vec3 tilted = Vec3{0.5, 0.0, std::sqrt(3.0) / 2.0}, z{0, 0, 1};
  for (const double full : {255.0, 4095.0})
    for (int k = 1; k <= 3; ++k) {
      const std::string bits = full < 300 ? "8-bit" : "16-bit";
      cases.push_back({std::to_string(k) + "-voxel wall tilted 30 deg, 1 mm voxels, " + bits, tilted,
                       {1e-3, 1e-3, 1e-3}, k * voxel_along(tilted, {1e-3, 1e-3, 1e-3}), 0.5e-3, full});
      cases.push_back({std::to_string(k) + "-voxel wall across z, 1x1x3 mm voxels, " + bits, z, {1e-3, 1e-3, 3e-3},
                       k * 3e-3, 1.2e-3, full});
    }
  return cases;
}

/// Walls like an unseen 8-bit chest CT's: 2-4 voxels thick along m on 0.7 x 0.7 x 2.5 mm
/// voxels, the normal 20, 30 and 45 deg off z (the coarse axis) and turned 30 deg about it
/// (tilted to every axis of the grid), a PSF of about a voxel along m (the blurred
/// partial-volume edge), 3 % noise, stored as 8-bit integers (clamped to 0..255).
inline std::vector<WallCase> scan_wall_cases() {
  std::vector<WallCase> cases;
  const Vec3 sp{0.7e-3, 0.7e-3, 2.5e-3};
  for (const double deg : {20.0, 30.0, 45.0})
    for (int k = 2; k <= 4; ++k) {
      const double a = deg * M_PI / 180.0, b = 30.0 * M_PI / 180.0;
      const Vec3 m{std::sin(a) * std::cos(b), std::sin(a) * std::sin(b), std::cos(a)};
      const double vox = voxel_along(m, sp);
      cases.push_back({std::to_string(k) + "-voxel wall " + std::to_string(int(deg)) +
                           " deg off z, 0.7x0.7x2.5 mm voxels, 8-bit, 3 % noise",
                       m, sp, k * vox, 0.5 * vox, 255.0, 0.03, {0.044, 0.044, 0.050}});
    }
  return cases;
}

/// A reproducible noise sample of unit standard deviation for the voxel nearest x (uniform,
/// from a hash of its indices): the same voxel reads the same noise in every snapshot.
inline double voxel_noise(const Vec3& x, const Vec3& sp) {
  std::uint64_t h = std::uint64_t(std::lround(x.x / sp.x)) * 0x9E3779B97F4A7C15ull ^
                    std::uint64_t(std::lround(x.y / sp.y)) * 0xC2B2AE3D27D4EB4Full ^
                    std::uint64_t(std::lround(x.z / sp.z)) * 0x165667B19E3779F9ull;
  h ^= h >> 33;
  h *= 0xFF51AFD7ED558CCDull;
  h ^= h >> 33;
  return std::sqrt(12.0) * (double(h >> 11) / double(1ull << 53) - 0.5);
}

/// The wall's field with the capsule of radius `cut` [m] round the segment a-b removed
/// (nothing removed where cut = 0; with noise, the noise stays where the drill cut, as a
/// scan's background): the material fraction through the PSF (wall across m,
/// centred at c, times the outside of the capsule), stored as integers 0..full, tau at
/// half of full (value - full / 2: positive inside), gradients by central differences.
inline core::SampleField drilled_wall(const WallCase& wc, const Vec3& c, const Vec3& a, const Vec3& b, double cut,
                                      std::uint64_t version) {
  const std::array<int, 3> dims{int(wc.box.x / wc.sp.x) + 1, int(wc.box.y / wc.sp.y) + 1, int(wc.box.z / wc.sp.z) + 1};
  auto seg_dist = [&](const Vec3& x) {
    const Vec3 ab = b - a;
    const double l2 = dot(ab, ab), t = l2 > 0 ? std::clamp(dot(x - a, ab) / l2, 0.0, 1.0) : 0.0;
    return norm(x - (a + ab * t));
  };
  core::SampleField f = scan_like_field(
      dims, wc.sp,
      [&](const Vec3& x) {
        const double u = dot(wc.m, x - c);
        const double wall = phi((u + 0.5 * wc.w) / wc.sigma) - phi((u - 0.5 * wc.w) / wc.sigma);
        const double kept = cut > 0 ? phi((seg_dist(x) - cut) / wc.sigma) : 1.0;
        if (wc.noise <= 0) return std::round(wc.full * wall * kept) - 0.5 * wc.full;
        const double v = wc.full * (wall * kept + wc.noise * voxel_noise(x, wc.sp));
        return std::round(std::clamp(v, 0.0, wc.full)) - 0.5 * wc.full;
      },
      0.0, 1u);
  f.version = version;
  return f;
}

/// The app's drill on a wall's voxels (session/brush.h, "drill"): the wall's stored values
/// 0..full (8-bit: integers, the scan as loaded), then every application at centre c (the
/// proxy) with the user's force |F| moves each voxel within `radius` toward empty (0) by
/// a w / f, a = rate dt max(0, |F| - threshold), w = 1 - smoothstep(radius (1 - falloff),
/// radius, r), f = 1 + v / full (density scale = the material-empty range): the channel's
/// edge is soft and its isosurface lies inside the brush's radius.
struct BrushedWall {
  core::Grid grid;
  std::vector<double> v;  ///< the values [0, full]
  double full = 255;

  BrushedWall(const WallCase& wc, const Vec3& c) : full(wc.full) {
    const core::SampleField f = drilled_wall(wc, c, c, c, 0.0, 0);
    grid = f.grid;
    v.resize(f.samples.size());
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = double(f.samples[i].value) + 0.5 * wc.full;
  }
  void drill(const Vec3& c, double radius, double falloff, double a) {
    const double inner = radius * (1 - falloff);
    for (int z = 0; z < grid.dims[2]; ++z)
      for (int y = 0; y < grid.dims[1]; ++y)
        for (int x = 0; x < grid.dims[0]; ++x) {
          const double r = norm(grid.to_world({double(x), double(y), double(z)}) - c);
          if (!(r < radius)) continue;
          const double t = std::clamp((r - inner) / (radius - inner), 0.0, 1.0), w = 1 - t * t * (3 - 2 * t);
          double& s = v[grid.index(x, y, z)];
          s = std::max(s - a * w / (1 + s / full), 0.0);
        }
  }
  /// The field the servo reads: value - full / 2 (positive inside), central-difference gradients.
  core::SampleField field(std::uint64_t version) const {
    core::SampleField f;
    f.grid = grid;
    f.samples.resize(v.size());
    const auto& d = grid.dims;
    const Vec3 sp = grid.spacing_m;
    auto at = [&](int x, int y, int z) { return v[grid.index(x, y, z)]; };
    for (int z = 0; z < d[2]; ++z)
      for (int y = 0; y < d[1]; ++y)
        for (int x = 0; x < d[0]; ++x) {
          const int x0 = std::max(x - 1, 0), x1 = std::min(x + 1, d[0] - 1);
          const int y0 = std::max(y - 1, 0), y1 = std::min(y + 1, d[1] - 1);
          const int z0 = std::max(z - 1, 0), z1 = std::min(z + 1, d[2] - 1);
          core::Sample& s = f.samples[grid.index(x, y, z)];
          s.value = float(at(x, y, z) - 0.5 * full);
          s.gx = float((at(x1, y, z) - at(x0, y, z)) / ((x1 - x0) * sp.x));
          s.gy = float((at(x, y1, z) - at(x, y0, z)) / ((y1 - y0) * sp.y));
          s.gz = float((at(x, y, z1) - at(x, y, z0)) / ((z1 - z0) * sp.z));
        }
    f.version = version;
    return f;
  }
};

}  // namespace isotouch::test
