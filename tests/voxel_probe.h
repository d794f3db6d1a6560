// voxel_probe.h - test helper: the trilinear value of a volume's raw voxels, computed
// directly from the voxels (an outside truth for the engine's FieldView / snapshots).
// Shared by tests/test_run_job.cpp and tests/test_edit_session.cpp.
#pragma once
#include <algorithm>
#include <cmath>

#include "isotouch/core/vec3.h"
#include "isotouch/engine/volume.h"

namespace isotouch::test {

/// Trilinear value of `v`'s voxels at grid-world point `p` [m] (Grid: origin + spacing *
/// index, no direction); NaN outside the box of voxel centres.
inline double trilinear_grid(const engine::Volume& v, const core::Vec3& p) {
  const double idx[3] = {(p.x - v.grid.origin_m.x) / v.grid.spacing_m.x, (p.y - v.grid.origin_m.y) / v.grid.spacing_m.y,
                         (p.z - v.grid.origin_m.z) / v.grid.spacing_m.z};
  int i0[3];
  double fr[3];
  for (int a = 0; a < 3; ++a) {
    if (!(idx[a] >= 0 && idx[a] <= v.grid.dims[std::size_t(a)] - 1)) return std::nan("");
    i0[a] = std::min(int(std::floor(idx[a])), std::max(0, v.grid.dims[std::size_t(a)] - 2));
    fr[a] = idx[a] - i0[a];
  }
  double s = 0;
  for (int c = 0; c < 8; ++c) {
    double w = 1;
    int ix[3];
    for (int a = 0; a < 3; ++a) {
      const int b = (c >> a) & 1;
      w *= b ? fr[a] : 1 - fr[a];
      ix[a] = std::min(i0[a] + b, v.grid.dims[std::size_t(a)] - 1);
    }
    s += w * v.voxels[v.grid.index(ix[0], ix[1], ix[2])];
  }
  return s;
}

}  // namespace isotouch::test
