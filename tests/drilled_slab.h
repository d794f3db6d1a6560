// drilled_slab.h - test helper: a slab of material with a hole drilled along z, made by hand
// (the truth for the channel's measurement and its picture). Shared by
// tests/test_drill_channel.cpp and tests/test_run_job.cpp.
#pragma once
#include <cmath>

#include "isotouch/engine/volume.h"

namespace isotouch::test {

/// A slab of material (1000; inside above an isovalue of 500, outside 0) for z in [10, 20] mm
/// on 0.5 mm voxels (41 x 41 x 61), with, when `hole`, a hole along the z axis through
/// (10, 10) mm whose radius at height z [mm] is radius(z) [mm].
inline engine::Volume drilled_slab(double (*radius)(double), bool hole) {
  engine::Volume v;
  v.grid.dims = {41, 41, 61};
  v.grid.spacing_m = {0.5e-3, 0.5e-3, 0.5e-3};
  v.voxels.resize(v.grid.voxel_count());
  for (int z = 0; z < 61; ++z)
    for (int y = 0; y < 41; ++y)
      for (int x = 0; x < 41; ++x) {
        const double zm = z * 0.5, rho = std::hypot(x * 0.5 - 10, y * 0.5 - 10);
        const bool in_slab = zm >= 10 && zm <= 20;
        v.voxels[v.grid.index(x, y, z)] = in_slab && !(hole && rho < radius(zm)) ? 1000.0f : 0.0f;
      }
  return v;
}

}  // namespace isotouch::test
