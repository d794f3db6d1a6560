// isosurface.h - the isosurface {tau, inside} test, written once for the whole project
// (HRI, the baselines, scripts, sweeps, surface distance). Part of isotouch::core.
#pragma once
#include <cstdint>

#include "isotouch/core/vec3.h"

namespace isotouch::core {

/// Which side of the isovalue is "inside" the object.
enum class InsideIs : std::uint8_t {
  kAbove,  ///< value > tau is inside (CT density, the HRI paper's B(v) = 1)
  kBelow,  ///< value < tau is inside (signed distance fields, negative inside)
};

/// "above" / "below" (scene files, reports).
constexpr const char* to_string(InsideIs i) { return i == InsideIs::kAbove ? "above" : "below"; }

/// Signed excess of `value` over the isovalue tau: > 0 inside, <= 0 outside (the surface
/// itself, excess 0, counts as outside). NaN counts as outside (-1), so a NaN voxel or a
/// NaN background (FieldView, outside the grid) is never inside an object.
constexpr double iso_excess(double value, double tau, InsideIs inside) {
  const double e = inside == InsideIs::kAbove ? value - tau : tau - value;
  return e == e ? e : -1.0;
}

/// The isosurface f = tau of a field, with its inside.
struct Isosurface {
  double tau = 0.0;                    ///< isovalue (value units)
  InsideIs inside = InsideIs::kAbove;  ///< which side of tau is the object

  /// See iso_excess().
  constexpr double excess(double value) const { return iso_excess(value, tau, inside); }
  /// True where `value` is inside the object (excess > 0; NaN is outside).
  constexpr bool contains(double value) const { return excess(value) > 0.0; }
  /// The gradient of the excess from the gradient of the value: points into the object,
  /// so the outward normal is -excess_gradient / |.|.
  constexpr Vec3 excess_gradient(const Vec3& value_gradient) const {
    return inside == InsideIs::kAbove ? value_gradient : -value_gradient;
  }
  /// The outward direction (out of the object, not normalized) from the value gradient.
  constexpr Vec3 outward(const Vec3& value_gradient) const {
    return inside == InsideIs::kAbove ? -value_gradient : value_gradient;
  }
  /// A finite value that is outside this isosurface and no nearer to it than any value
  /// in [lo, hi] (the range of a volume): min(lo, tau) for kAbove, max(hi, tau) for
  /// kBelow. Used as the FieldView background so that outside the grid is outside the object.
  constexpr double outside_value(double lo, double hi) const {
    return inside == InsideIs::kAbove ? (lo < tau ? lo : tau) : (hi > tau ? hi : tau);
  }
};

}  // namespace isotouch::core
