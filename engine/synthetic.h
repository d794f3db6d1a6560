// synthetic.h - analytic test volumes with known truth.
#pragma once
#include "isotouch/engine/core_names.h"
#include <array>
#include <cstdint>

#include "isotouch/engine/volume.h"

namespace isotouch::engine {

/// Solid sphere as a signed distance in millimetres, positive inside:
/// value(x) = (radius - |x - centre|) * 1000, so the isosurface tau = 0 is the sphere
/// of radius `radius_vox * spacing_m` [m] around the grid centre + `centre_offset_vox`.
/// @param dims voxels per axis; @param spacing_m isotropic voxel size [m]
Volume make_sphere(std::array<int, 3> dims, double spacing_m, double radius_vox,
                   std::array<double, 3> centre_offset_vox = {0, 0, 0});

/// value(x) = a . x (world [m]) + b: central differences are exact on it.
Volume make_linear(std::array<int, 3> dims, core::Vec3 spacing_m, core::Vec3 a, double b);

/// Uniform random values in [lo, hi) from a fixed seed (for GPU-vs-CPU checks).
Volume make_random(std::array<int, 3> dims, core::Vec3 spacing_m, float lo, float hi,
                   std::uint32_t seed);

}  // namespace isotouch::engine
