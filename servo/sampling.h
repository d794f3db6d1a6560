// sampling.h - free-function spellings of core::FieldView's reads (tests, apps, scripts).
// The renderers call FieldView directly; these forward to it, so both give the same numbers.
#pragma once
#include "isotouch/servo/core_names.h"
#include "isotouch/core/field_view.h"

namespace isotouch::servo {

/// Trilinear value and gradient blend at `world_m`: FieldView::value_gradient.
inline FieldValue sample_trilinear(const FieldView& field, const Vec3& world_m) {
  return field.value_gradient(world_m);
}
/// Trilinear value only: FieldView::value.
inline double sample_value(const FieldView& field, const Vec3& world_m) { return field.value(world_m); }
/// Central differences with half steps h [m]: FieldView::central_difference.
inline Vec3 central_difference_gradient(const FieldView& field, const Vec3& world_m, const Vec3& h_m) {
  return field.central_difference(world_m, h_m);
}
/// Exact gradient of the trilinear interpolant: FieldView::trilinear_gradient.
inline Vec3 trilinear_field_gradient(const FieldView& field, const Vec3& world_m) {
  return field.trilinear_gradient(world_m);
}

}  // namespace isotouch::servo
