// field_builders.h - test helper: a SampleField sampled from an analytic value and gradient at
// every voxel centre (the truth the brick-field and thin-feature tests compare against).
#pragma once
#include <array>
#include <functional>

#include "isotouch/core/sample_field.h"

namespace isotouch::test {

/// `dims` voxels of `spacing` [m] from `origin` [m]; each sample is value(p) and grad(p) at the
/// voxel's world position p, as floats.
inline core::SampleField sample_analytic(std::array<int, 3> dims, core::Vec3 spacing, core::Vec3 origin,
                                         const std::function<double(const core::Vec3&)>& value,
                                         const std::function<core::Vec3(const core::Vec3&)>& grad) {
  core::SampleField f;
  f.grid.dims = dims;
  f.grid.spacing_m = spacing;
  f.grid.origin_m = origin;
  f.samples.resize(f.grid.voxel_count());
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        const core::Vec3 p = f.grid.to_world({double(x), double(y), double(z)});
        const core::Vec3 g = grad(p);
        f.samples[f.grid.index(x, y, z)] = {float(value(p)), float(g.x), float(g.y), float(g.z)};
      }
  return f;
}

}  // namespace isotouch::test
