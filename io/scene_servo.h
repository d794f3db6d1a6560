// scene_servo.h - a renderer's parameters as a scene's "servo" section, and which of them a
// scene cannot carry. A session made in a program (Python's LiveSession(volume, params=...,
// record=...)) writes its scene beside the recording; `isotouch replay` rebuilds the renderer
// from that scene, so the section must give back the same parameters bit for bit.
#pragma once
#include <string>

#include "isotouch/servo/hri.h"

namespace isotouch::io {

/// The "servo" section for `hri` (docs/user-guide.md's field table): variant, stiffness_n_per_m,
/// damping_n_s_per_m, plane_update_period, rate_hz, force_limit_n, intersection,
/// intersection_steps, normal, force_shading, recovery_time_s, friction (when any), tool
/// (radius_mm when > 0, the millimetres whose 1e-3 * mm is the radius where there are such:
/// not for 4.5 mm), as a JSON object whose numbers read back exactly (17 digits).
std::string servo_section_json(const servo::HriParams& hri);

/// The first field of `wanted` that `parsed` (the scene's renderer read back, world_per_device
/// aside: the scene's device section owns it) does not hold equal, as "name value" (e.g.
/// "velocity_cutoff_hz 150"), or "" when every field is equal: a field a scene has no key
/// for (max_reach_m, velocity_cutoff_hz, max_speed_m_s, march_budget, edit_period_s,
/// short_way) or one its parser would change. The paper variant's intersection and normal
/// are not compared: it renders Figure 2's rules whatever they say (servo/hri.h).
std::string unrecordable_field(const servo::HriParams& wanted, const servo::HriParams& parsed);

}  // namespace isotouch::io
