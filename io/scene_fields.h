// scene_fields.h - the scene file's fields, in one table: the parser accepts exactly these
// keys in each section (io/scene.cpp asks scene_keys), and docs/user-guide.md's field tables
// list exactly these, with these units (tests/test_scene.cpp reads both), so neither drifts.
// The sub-objects described in prose (servo.friction, servo.tool, an engine pass's
// parameters) keep their lists in the parser.
#pragma once
#include <set>
#include <string>
#include <string_view>

namespace isotouch::io {

/// One field: its section ("" top level, "volume", ..., "edits.brush", "edits.timeline" for the
/// fields a timed brush adds to a brush's), its key and its unit as the docs' table gives it
/// ("" when the table has none or the field has no unit).
struct SceneField {
  std::string_view section, key, unit;
};

inline constexpr SceneField kSceneFields[] = {
    {"", "name", ""}, {"", "description", ""}, {"", "volume", ""}, {"", "isovalue", "the volume's units"},
    {"", "inside", ""}, {"", "servo", ""}, {"", "device", ""}, {"", "script", ""}, {"", "engine", ""},
    {"", "edits", ""}, {"", "outputs", ""},
    {"volume", "path", ""}, {"volume", "synthetic", ""}, {"volume", "dims", "voxels"}, {"volume", "spacing_m", "m"},
    {"volume", "radius_vox", "voxels"}, {"volume", "attribution", ""},
    {"servo", "stiffness_n_per_m", "N/m"}, {"servo", "damping_n_s_per_m", "N s/m"},
    {"servo", "plane_update_period", "ticks"}, {"servo", "rate_hz", "Hz"}, {"servo", "force_limit_n", "N"},
    {"servo", "variant", ""}, {"servo", "intersection", ""}, {"servo", "intersection_steps", ""},
    {"servo", "normal", ""}, {"servo", "force_shading", ""}, {"servo", "recovery_time_s", "s"},
    {"servo", "friction", ""}, {"servo", "tool", ""}, {"servo", "allow_unstable_stiffness", ""},
    {"device", "mass_kg", "kg"}, {"device", "damping_n_s_per_m", "N s/m"}, {"device", "coulomb_friction_n", "N"},
    {"device", "encoder_resolution_m", "m"}, {"device", "force_max_n", "N"}, {"device", "hand_stiffness_n_per_m", "N/m"},
    {"device", "hand_damping_n_s_per_m", "N s/m"}, {"device", "substeps", ""},
    {"device", "workspace_scale", "world m per device m"},
    {"script", "ray_origin_frac", "fractions of the volume box"}, {"script", "ray_direction", ""},
    {"script", "stroke_direction", ""}, {"script", "approach_distance_m", "m"}, {"script", "approach_speed_m_s", "m/s"},
    {"script", "press_depth_m", "m"}, {"script", "press_speed_m_s", "m/s"}, {"script", "hold_s", "s"},
    {"script", "stroke_length_m", "m"}, {"script", "stroke_speed_m_s", "m/s"}, {"script", "rest_s", "s"},
    {"script", "lift_retrace", ""},
    {"engine", "passes", ""}, {"engine", "mode", ""}, {"engine", "samples", ""},
    {"edits", "brush", ""}, {"edits", "every_ticks", "ticks"}, {"edits", "button", "s"}, {"edits", "timeline", ""},
    {"edits", "history_limit_mib", "MiB"}, {"edits", "write_vdb", ""}, {"edits", "write_nrrd", ""},
    {"edits", "write_stl", ""},
    {"edits.brush", "kind", ""}, {"edits.brush", "radius_mm", "mm"},
    {"edits.brush", "strength", "value units per application; smooth: a fraction"},
    {"edits.brush", "falloff", "fraction of the radius"}, {"edits.brush", "force_threshold_n", "N"},
    {"edits.brush", "rate", "value units per N s"}, {"edits.brush", "removal_per_n_s", "fraction of \\|material - empty\\| per N s"},
    {"edits.brush", "density_scale", "value units"}, {"edits.brush", "material", "value units"},
    {"edits.brush", "empty", "value units"},
    {"edits.timeline", "t_s", "s"}, {"edits.timeline", "at", "mm, physical frame"}, {"edits.timeline", "duration_s", "s"},
    {"edits.timeline", "force_n", "N"},
    {"outputs", "trace_csv", ""}, {"outputs", "plots", ""},
};

/// The keys of `section` in kSceneFields.
inline std::set<std::string> scene_keys(std::string_view section) {
  std::set<std::string> keys;
  for (const SceneField& f : kSceneFields)
    if (f.section == section) keys.emplace(f.key);
  return keys;
}

}  // namespace isotouch::io
