// touch_plan.h - the scripted hand's touch planned offline on the true isosurface.
//
// The ray script (sim::make_touch_script) strokes along a straight line, re-cast along the
// first contact's normal: on a curved or irregular object the hand's target leaves the
// surface or sinks far under it. This planner works on the trilinear isosurface that
// `eval` measures against (surface_distance.h), never on a renderer's proxy, so every
// renderer (HRI, the baselines) gets the same hand path and a renderer that lets go still
// shows it: the hand aims along the surface normal, presses to a depth the force limit
// allows, strokes along the surface (each sample projected onto the true isosurface and
// pressed along the local normal) and lifts along the normal where the stroke ends.
#pragma once
#include <limits>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"
#include "isotouch/servo/hri.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"

namespace isotouch::eval {

/// What the planner chose, with the script (all points grid-world [m]).
struct TouchPlan {
  sim::TouchScript script;
  /// The press depth d [m] of the hand's target under the contact point, along its normal.
  double press_depth_m = 0;
  /// The press depth [m] under each stroke point (stroke_surface_m), along its normal (today
  /// one depth for all: press_depth_m).
  std::vector<double> stroke_depth_m;
  double min_press_depth_m = 0;  ///< the smallest of stroke_depth_m [m]
  /// The stroke's start direction [deg] around the contact normal from stroke_direction's
  /// projection (counter-clockwise seen from outside), and how many directions were tried.
  double direction_deg = 0;
  int directions_tried = 0;
  /// d that the force allows alone: f F_limit (1/K + 1/K_hand) scaled to world [m] (the
  /// renderer's spring K and the hand's spring in series hold the force at f F_limit).
  double force_depth_m = 0;
  /// Thinnest wall under the stroke [m] (along -normal from each stroke point, the box's
  /// edge not counted), +inf where every wall is thicker than force_depth_m /
  /// thickness_fraction. The depth is at most thickness_fraction of it, so the hand never
  /// comes nearer the far side.
  double min_thickness_m = std::numeric_limits<double>::infinity();
  /// The stroke's surface points and outward unit normals, in stroke order (first: contact).
  std::vector<core::Vec3> stroke_surface_m, stroke_normal;
  double stroke_length_m = 0;  ///< the length walked on the surface [m] (short where it ended)
};

struct TouchPlanOptions {
  /// f: the pressed hand's static force as a fraction of hri.force_limit_n (below 1 so the
  /// force stays under the limit while the hand moves).
  double force_fraction = 0.6;
  /// Largest share of the wall's thickness the press may reach.
  double thickness_fraction = 0.4;
};

/// The press depth [m, world] at which the hand's static force is `force_fraction` of the
/// force limit: K (renderer) and the hand spring in series, device metres scaled by
/// hri.world_per_device.
double force_press_depth_m(const servo::HriParams& hri, const sim::SimDeviceParams& device, double force_fraction);

/// Plans the touch on `truth` (dense samples; its isosurface {hri.tau, hri.inside} is the one
/// measured against). From `p`: the ray (ray_origin_frac, ray_direction) that finds the
/// contact, stroke_direction (projected on the tangent plane), stroke_length_m, the speeds,
/// hold_s, rest_s, approach_distance_m; press_depth_m is replaced by the planned depth.
/// The stroke walks in steps of half the smallest spacing (at most 10000): each step moves
/// along the tangent, is projected to the nearest isosurface point, and carries the tangent
/// over to that point's tangent plane; the walk ends early where no surface is found near or
/// the nearest is another sheet's (its normal turned more than 90 degrees). The stroke starts along stroke_direction unless its shallowest press is under half the
/// force's depth times the share of the length walked (the wall thins or the surface ends
/// along it): then it starts along the best of 8 directions around the contact normal by
/// that score (the shallowest press times the share walked). Still under that mark: the best
/// start within 12 mm of the contact on the surface; still under it (a thin rib under the
/// ray): the best of the first contacts of 25 rays parallel to the scene's from a grid over
/// the middle 60 % of the box, by the same score.
/// @throws std::runtime_error as sim::make_touch_script (the ray never meets the surface).
TouchPlan plan_touch(const core::SampleField& truth, const servo::HriParams& hri, const sim::SimDeviceParams& device,
                     const sim::ScriptParams& p, const TouchPlanOptions& options = {});

}  // namespace isotouch::eval
