// sampling.h - trilinear reads of a published SampleField (no allocation, no lock).
#pragma once
#include "sample_field.h"

namespace isotouch::servo {

/// Trilinear value and trilinear-interpolated gradient at a world point.
struct FieldValue {
  double value = 0;  ///< trilinear value (value units); NaN where a voxel is NaN
  Vec3 gradient;     ///< trilinear blend of the published gradient samples [units/m]
};

/// Trilinear interpolation of value and gradient at `world_m` (volume frame [m]).
/// Outside the grid the position is clamped to the border (clamp-to-edge), so a HIP
/// that leaves the volume reads the border values. An empty grid gives NaN.
FieldValue sample_trilinear(const SampleField& field, const Vec3& world_m);

/// Trilinear value only (cheaper: one channel).
double sample_value(const SampleField& field, const Vec3& world_m);

/// Central differences of the trilinear value at `world_m` with half steps h [m] per
/// axis: ((f(x + h_x e_x) - f(x - h_x e_x)) / (2 h_x), ...) [units/m]. The same numbers as
/// six sample_value() calls, with the cell lookups shared (the paper's SurfaceNormal).
/// Non-finite input or an empty grid gives NaN components.
Vec3 central_difference_gradient(const SampleField& field, const Vec3& world_m, const Vec3& h_m);

/// Exact gradient of the trilinear value field at `world_m` (derivative of the
/// interpolant, piecewise bilinear) [units/m]. Used by error metrics, not by HRI.
Vec3 trilinear_field_gradient(const SampleField& field, const Vec3& world_m);

}  // namespace isotouch::servo
