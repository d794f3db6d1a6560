// script.h - scripted operator motion: approach, press, stroke along the surface, lift.
#pragma once
#include <string>
#include <vector>

#include "hri.h"
#include "sample_field.h"

namespace isotouch::servo {

/// Parameters of the touch script (world [m], s).
struct ScriptParams {
  Vec3 ray_origin_frac{0.5, 0.5, 1.2};  ///< ray start as a fraction of the volume box
  Vec3 ray_direction{0, 0, -1};         ///< ray direction (volume frame, any length)
  Vec3 stroke_direction{1, 0, 0};       ///< projected on the tangent plane at contact
  double approach_distance_m = 0.010;   ///< start this far outside the surface
  double approach_speed_m_s = 0.020;
  double press_depth_m = 0.008;         ///< hand target depth below the surface
  double press_speed_m_s = 0.020;
  double hold_s = 0.2;                  ///< dwell at depth before stroking
  double stroke_length_m = 0.040;       ///< length of the stroke along the surface
  double stroke_speed_m_s = 0.040;
  double rest_s = 0.1;                  ///< still time at start and end
};

/// A piecewise-linear hand-target trajectory in world [m].
struct TouchScript {
  struct Waypoint {
    double t_s;
    Vec3 pos_m;
  };
  std::vector<Waypoint> waypoints;  ///< sorted by t_s
  Vec3 contact_point_m;             ///< where the ray first met the isosurface
  Vec3 contact_normal;              ///< outward unit normal there
  double duration_s = 0;
  /// Phase boundaries [s]: approach start, press start, stroke start, lift start, end.
  double t_press = 0, t_stroke = 0, t_lift = 0;

  /// Hand target position and velocity at time t (clamped to the ends).
  void at(double t_s, Vec3& pos_m, Vec3& vel_m_s) const;
};

/// First crossing of the isosurface along a ray (march + bisection on the trilinear
/// field). Returns false if the ray starts inside or never crosses within max_dist_m.
bool find_surface(const SampleField& field, const HriRenderer& classify, const Vec3& origin_m,
                  const Vec3& dir_unit, double max_dist_m, Vec3& hit_m);

/// Build the script on `field`. Throws std::runtime_error with a reason (naming the
/// ray) when the ray never meets the isosurface or starts inside it.
TouchScript make_touch_script(const SampleField& field, const HriParams& hri,
                              const ScriptParams& params);

}  // namespace isotouch::servo
