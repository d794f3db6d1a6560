// drill_channel.h - how a drilled channel came out, measured on the voxels (outside the
// servo and the brush): its open radius along the burr's path, and the breakthrough (the
// force drop when the burr comes out through the far side) in a run's trace.
#pragma once
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"
#include "isotouch/engine/volume.h"

namespace isotouch::eval {

/// Open radius of a drilled channel.
struct ChannelFigures {
  bool measured = false;       ///< some slice of the path crossed material of `before`
  int slices = 0;              ///< slices measured (where `before` was material on the path)
  double min_open_radius_m = 0;  ///< the narrowest slice's open radius [m]
  double min_at_depth_m = 0;     ///< its depth along the axis from the first slice [m]
  double min_fraction = 0;       ///< min_open_radius_m / burr radius
  core::Vec3 min_centre_m;       ///< the path's centre on the narrowest slice (grid-world [m])
};

/// The trilinear value of `v` at grid-world `x_m` [m] (indices clamped to the grid).
double volume_trilinear(const engine::Volume& v, const core::Vec3& x_m);

/// The channel the burr left: at each slice perpendicular to `axis` (unit, the drilling
/// direction), a quarter voxel apart along the burr centres' path `centres` (grid-world [m],
/// in drilling order), where the trilinear `before` volume was material at the burr centre,
/// the open radius is the largest rho (0.05 voxel steps, up to 1.5 r) such that every point
/// of the disc of radius rho around the path's centre at that depth (24 angles, radii in
/// 0.05 voxel steps) is outside the isosurface of the trilinear `after` volume. Frames:
/// grid-world [m]; `before` and `after` share one grid.
ChannelFigures measure_channel(const engine::Volume& before, const engine::Volume& after, const core::Isosurface& iso,
                               const std::vector<core::Vec3>& centres, const core::Vec3& axis, double burr_radius_m);

/// The breakthrough in a drilling run's trace.
struct Breakthrough {
  bool found = false;
  double t_s = 0;          ///< the tick |F| fell to a tenth of the threshold [s]
  double from_n = 0;       ///< largest |F| over the `window_s` before it [N]
  double to_n = 0;         ///< |F| at t_s [N]
  double fall_s = 0;       ///< from the last tick at or above 90 % of from_n to t_s [s]
};

/// The first tick k of `drilling` ticks (button down) where |F| (`force_n`, per tick at
/// times `t_s`), after it was above `threshold_n` while drilling, falls to a tenth of the
/// threshold and stays there for `hold_s` while the button is down: the burr broke through
/// and nothing holds it any more.
Breakthrough find_breakthrough(const std::vector<double>& t_s, const std::vector<double>& force_n,
                               const std::vector<char>& drilling, double threshold_n, double hold_s = 0.05,
                               double window_s = 0.05);

}  // namespace isotouch::eval
