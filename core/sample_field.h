// sample_field.h - the plane-ready sample format the engine publishes and the servo reads.
// Part of isotouch::core (engine/ writes it, servo/ reads it through core::FieldView).
#pragma once
#include <cstdint>
#include <limits>
#include <vector>

#include "grid.h"
#include "isosurface.h"
#include "vec3.h"

namespace isotouch::core {

/// One sample per voxel: the scalar value and its gradient.
/// Layout = GLSL `vec4(value, gx, gy, gz)` written by shaders/gradient.comp (16 bytes).
struct Sample {
  float value;  ///< scalar value (scanner units, HU, or signed distance [m])
  float gx;     ///< d value / dx [value units / m], grid-world frame
  float gy;     ///< d value / dy
  float gz;     ///< d value / dz
};
static_assert(sizeof(Sample) == 16, "Sample must match GLSL vec4");

/// The dense sample field: one Sample per voxel, x fastest, then y, then z.
/// Immutable once published (engine/ publishes a new one after each edit). Read it
/// through core::FieldView (field_view.h).
struct SampleField {
  Grid grid;
  std::vector<Sample> samples;  ///< grid.voxel_count() entries
  std::uint64_t version = 0;    ///< increases with every publication
  /// The value of every voxel outside the grid (its gradient is zero there): FieldView
  /// interpolates toward it across the border cells instead of clamping to the edge.
  /// NaN (the default) means "no data": outside every isosurface (iso_excess(NaN) < 0),
  /// so a HIP outside the volume is outside the object. A publisher that knows the
  /// isosurface sets a finite outside value (Isosurface::outside_value), which closes an
  /// object cut by the volume border with a surface half a voxel beyond the last sample.
  float background = std::numeric_limits<float>::quiet_NaN();
};

/// The background value that puts everything outside `f`'s grid outside `iso`:
/// Isosurface::outside_value over the finite sample values (tau itself when there are
/// none). A scan of the samples: call it when publishing, never in the servo tick.
inline float outside_background(const SampleField& f, const Isosurface& iso) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const Sample& s : f.samples) {
    if (!(s.value == s.value) || s.value - s.value != 0.0f) continue;  // NaN or Inf
    lo = s.value < lo ? s.value : lo;
    hi = s.value > hi ? s.value : hi;
  }
  return float(iso.outside_value(lo, hi));
}

}  // namespace isotouch::core
