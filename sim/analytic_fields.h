// analytic_fields.h - sample fields with exact values and gradients (known truth).
// For servo-side experiments and tests that must not depend on the engine or Vulkan.
#pragma once
#include "isotouch/sim/servo_names.h"
#include "isotouch/core/sample_field.h"

namespace isotouch::sim {

/// Half-space wall: value = 1000 * (n . (c - x)) [mm], positive inside (behind the plane
/// through c with outward unit normal n). Exact under trilinear interpolation.
/// @param dims voxels per axis; @param h voxel size [m]; origin at 0.
SampleField plane_field(Vec3 n, Vec3 c, int dims = 32, double h = 1e-3);

/// Solid sphere of radius r [m] around c: value = 1000 * (r - |x - c|) [mm].
SampleField sphere_field(Vec3 c, double r, int dims = 48, double h = 1e-3);

/// Hollow spherical shell of thickness `thickness` [m] around radius r:
/// value = 1000 * (thickness/2 - | |x - c| - r |) [mm], positive inside the shell wall.
SampleField shell_field(Vec3 c, double r, double thickness, int dims = 96, double h = 1e-3);

}  // namespace isotouch::sim
