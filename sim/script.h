// script.h - scripted operator motion: approach, press, stroke along the surface, lift.
#pragma once
#include "isotouch/sim/servo_names.h"
#include <string>
#include <vector>

#include "isotouch/servo/hri.h"
#include "isotouch/core/sample_field.h"

namespace isotouch::sim {

/// Accepted range of each ray_origin_frac component (fractions of the volume box).
inline constexpr double kRayOriginFracMin = -2.0;
inline constexpr double kRayOriginFracMax = 3.0;

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
  /// The lift retraces the tool's path (TouchScript::retrace_lift, which the run calls with
  /// the path): an operator withdraws a burr along the channel it drilled, not along the
  /// straight line the hand aimed at when the hand drifted while drilling.
  bool lift_retrace = false;
  /// How the hand path is made. "ray": this file's make_touch_script (the press at
  /// press_depth_m, the stroke re-cast along the first contact's normal). "surface": planned
  /// on the true isosurface (eval/touch_plan.h, which the run calls): the press at the depth
  /// where the hand's static force is press_force_fraction of the force limit, the stroke
  /// following the surface; press_depth_m is not used.
  std::string plan = "ray";
  double press_force_fraction = 0.6;  ///< f of the "surface" plan (0, 0.95]
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

  /// ScriptParams::lift_retrace: the run calls retrace_lift() before the lift begins.
  bool lift_retrace = false;

  /// Hand target position and velocity at time t (clamped to the ends).
  void at(double t_s, Vec3& pos_m, Vec3& vel_m_s) const;
  /// Replaces the straight lift by one through `tool_path` backwards (world [m], in the
  /// order the tool took it): from the hand's target at t_lift to the path's last point,
  /// along the path to its first, then to the lift's end point, at a steady speed over the
  /// time the straight lift took; the rest after it and every earlier waypoint are kept
  /// (duration_s unchanged). An empty path leaves the script as it is.
  void retrace_lift(const std::vector<Vec3>& tool_path);
};

/// First crossing of the isosurface along a ray (march + bisection on the trilinear
/// field). Returns false if the ray starts inside or never crosses within max_dist_m.
/// Only the part of the ray inside the volume box is marched, in steps of a quarter of
/// the smallest spacing, or longer where that part would take more than 2^21 steps: the
/// cost is bounded whatever the spacing, the ray origin or max_dist_m.
/// `max_steps` caps the samples of the march (the stroke uses 1024 per point).
bool find_surface(const SampleField& field, const HriRenderer& classify, const Vec3& origin_m,
                  const Vec3& dir_unit, double max_dist_m, Vec3& hit_m, long max_steps = 1L << 21);

/// Build the script on `field`. Throws std::runtime_error with a reason (naming the
/// ray, positions in mm) when the ray never meets the isosurface or starts inside it, or
/// when a ray_origin_frac component is outside [kRayOriginFracMin, kRayOriginFracMax].
/// The stroke has at most 10000 points whatever the grid.
TouchScript make_touch_script(const SampleField& field, const HriParams& hri,
                              const ScriptParams& params);

}  // namespace isotouch::sim
