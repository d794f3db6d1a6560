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

/// The wall's field with the capsule of radius `cut` [m] round the segment a-b removed
/// (nothing removed where cut = 0): the material fraction through the PSF (wall across m,
/// centred at c, times the outside of the capsule), stored as integers 0..full, tau at
/// half of full (value - full / 2: positive inside), gradients by central differences.
inline core::SampleField drilled_wall(const WallCase& wc, const Vec3& c, const Vec3& a, const Vec3& b, double cut,
                                      std::uint64_t version) {
  const std::array<int, 3> dims{int(0.024 / wc.sp.x) + 1, int(0.024 / wc.sp.y) + 1, int(0.036 / wc.sp.z) + 1};
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
        return std::round(wc.full * wall * kept) - 0.5 * wc.full;
      },
      0.0, 1u);
  f.version = version;
  return f;
}

}  // namespace isotouch::test
