// surface_distance.h - true distance from a point to the isosurface of the trilinear field.
//
// Used for the reported surface error (`error.surface_distance_m` of `isotouch run`, the
// CT rows of `isotouch report`). Not used by the servo (it allocates and can take
// milliseconds).
#pragma once
#include <cstddef>
#include <limits>

#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"

namespace isotouch::eval {

/// Result of distance_to_isosurface. All lengths in metres, points in the grid frame of
/// the field (world = origin + index * spacing, the frame the servo works in).
struct SurfaceDistance {
  /// Distance from the query point to `closest_m`, a point that lies exactly on the
  /// isosurface of the trilinear field (it is the linear-interpolation crossing on an
  /// edge of a sub-box, where the trilinear field is linear). +inf when `found` is false.
  double distance_m = std::numeric_limits<double>::infinity();
  /// Proven lower bound on the true distance: true distance is in [lower_bound_m, distance_m].
  double lower_bound_m = 0;
  core::Vec3 closest_m;       ///< the surface point found (grid frame [m])
  bool found = false;          ///< false: no isosurface within max_radius_m ("no surface within R")
  bool budget_exceeded = false;///< the box budget ran out: distance_m is still an upper bound
  double searched_radius_m = 0;///< radius of the ball that was searched completely
  std::size_t boxes = 0;       ///< boxes visited (cost)
};

struct SurfaceDistanceOptions {
  /// Give up beyond this distance [m]; 0 = 64 voxels (the smallest spacing).
  double max_radius_m = 0;
  /// Absolute accuracy [m]: distance_m - true distance <= tolerance_m; 0 = 1e-3 voxel.
  double tolerance_m = 0;
  /// Relative accuracy near the surface: a second pass brings the error below
  /// max(min_tolerance_m, relative_tolerance * distance) when that is tighter.
  double relative_tolerance = 1e-2;
  double min_tolerance_m = 0;  ///< 0 = 1e-6 voxel
  /// Most boxes examined before giving up with budget_exceeded (bounds the cost).
  std::size_t max_boxes = 4'000'000;
};

/// Distance from `p_m` (grid frame [m]) to the isosurface f = tau of the trilinear field
/// `servo::sample_value` reads (the same float values, the same cells).
///
/// Method (branch and bound, exact bounds): a trilinear function restricted to any
/// axis-aligned sub-box of a cell is again trilinear, so its range over the sub-box is
/// [min, max] of its 8 corner values, and a sub-box whose corners straddle tau contains
/// the surface, with an exact surface point wherever an edge's end values straddle tau
/// (the field is linear along an edge). Cells that straddle tau within a search radius
/// are the roots; boxes are visited nearest first (Euclidean distance from p to the box,
/// in metres with the real spacing), split in 8 while their lower bound is below the best
/// surface point found minus the tolerance. The radius starts at 2 voxels and doubles
/// until a surface point within it is found, up to max_radius_m.
///
/// Accuracy: the returned distance is that of a point on the surface (never too small)
/// and exceeds the true distance d by at most min(1e-3 voxel, max(1e-6 voxel, 0.01 d))
/// with the default options, unless budget_exceeded. Cost: about 4 sqrt(3) d / tolerance
/// boxes at the finest level for a point at distance d from a flat surface: a few
/// thousand boxes (well under a millisecond) within a voxel of the surface; d = 6 voxels
/// with 1e-3 voxel: ~3e4 boxes, a few ms.
/// Cells with a NaN/Inf corner hold no surface (the servo treats them as outside).
/// Only the surface inside the grid box counts; for p inside the box this is the distance
/// to the surface of the clamp-to-edge field as well.
/// @throws nothing; an empty grid or non-finite p gives found = false.
SurfaceDistance distance_to_isosurface(const core::SampleField& field, double tau,
                                       const core::Vec3& p_m,
                                       const SurfaceDistanceOptions& options = {});

/// The old first-order estimate |f(p) - tau| / |grad f(p)| (trilinear f, exact gradient of
/// the interpolant). Unbounded where the field is flat; kept only to show what it reported.
double first_order_distance(const core::SampleField& field, double tau, const core::Vec3& p_m);

}  // namespace isotouch::eval
