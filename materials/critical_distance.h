// critical_distance.h - the distance from anywhere in the scan to the nearest voxel of a
// critical material (the structures a drill must not touch), for the margin warning.
//
// An exact Euclidean distance transform of the critical voxels' centres on the scan's grid
// (Felzenszwalb & Huttenlocher's separable lower-envelope method, one pass per axis with the
// axis's own spacing, so anisotropic grids are exact). OpenVDB's level-set tools were not
// used: they need cubic voxels (scans are often not) and give a narrow band only, while the
// closest approach is wanted wherever the burr goes. Critical voxels are never removed
// (session::MaterialCut), so the field is built once and never goes stale.
#pragma once
#include <cstdint>
#include <vector>

#include "isotouch/core/grid.h"
#include "isotouch/core/vec3.h"

namespace isotouch::materials {

class CriticalDistance {
 public:
  /// The transform of the voxels whose id is flagged in `critical` (indexed by id; ids past
  /// its end are not critical). `ids`: one per voxel of `grid`, x fastest.
  /// @throws MaterialError if ids does not match the grid.
  CriticalDistance(const core::Grid& grid, const std::vector<std::uint8_t>& ids, const std::vector<bool>& critical);

  /// True if some voxel is critical (else every distance is +infinity).
  bool any() const { return any_; }
  /// Distance [m] from voxel (x, y, z)'s centre to the nearest critical voxel centre (exact).
  double at(int x, int y, int z) const { return double(d_[grid_.index(x, y, z)]); }
  /// A lower bound of the distance [m] from grid-world point p [m] to the nearest critical
  /// voxel centre: max over the 8 surrounding voxel centres q of (at(q) - |p - q|) (the
  /// distance is 1-Lipschitz), exact at voxel centres, at most one cell diagonal short
  /// between them; outside the grid also at least p's distance to the grid's box. So a
  /// warning driven by it never comes later than the exact distance would give.
  double lower_bound(const core::Vec3& p) const;
  const core::Grid& grid() const { return grid_; }

 private:
  core::Grid grid_;
  std::vector<float> d_;  ///< [m] per voxel, x fastest
  bool any_ = false;
};

}  // namespace isotouch::materials
