// frame.h - what one frame of the sculpting window draws: the camera (orbit, pan, zoom),
// the cursor's ray, and the overlay primitives (HIP, VHIP, virtual plane, the force as an
// arrow coloured by |F|, the brush footprint, the hand target).
#pragma once
#include <array>
#include <vector>

#include "isotouch/session/live_session.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/apps/sculpt/tools.h"
#include "isotouch/engine/volume.h"

namespace isotouch::sculpt {

/// The orbit camera the mouse and keys steer.
struct CameraControl {
  engine::OrbitCamera cam;
  void orbit(double d_azimuth_deg, double d_elevation_deg);
  /// Moves the target by (dx, dy) fractions of the view's height in the picture plane.
  void pan(const engine::CameraView& view, const core::Grid& grid, double dx, double dy);
  void zoom_by(double factor);  ///< zoom *= factor, kept in [0.05, 50]
};

/// The grid-world ray through pixel (px, py) (fractional pixels allowed): origin and unit direction.
struct Ray {
  core::Vec3 origin, dir;
};
Ray cursor_ray(const engine::CameraView& view, int width, int height, double px, double py);

/// Blue -> green -> yellow -> red for s = |F| / force limit in [0, 1].
std::array<float, 3> force_colour(double s);

/// The overlay of one frame (grid-world). `size_m`: the size unit (0.6 x the largest spacing).
std::vector<gpu::RaycastPrim> overlay_prims(const session::Observed& obs, const core::Vec3& hand_m,
                                            const ToolState& tool, double force_limit_n, double size_m,
                                            bool button_down);

}  // namespace isotouch::sculpt
