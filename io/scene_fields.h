// scene_fields.h - the scene file's fields, in one table: the parser accepts exactly these
// keys in each section and checks each number against its range and takes its default from
// here (io/scene.cpp), and docs/user-guide.md's field tables list exactly these, with these
// units, ranges and defaults (tests/test_scene.cpp reads both), so neither drifts.
#pragma once
#include <set>
#include <string>
#include <string_view>

#include "isotouch/io/scene_field_range.h"

namespace isotouch::io {

/// One field: its section ("" top level, "volume", ..., "servo.friction", "edits.brush",
/// "edits.timeline" for the fields a timed brush adds to a brush's, "engine.passes.NAME" for
/// a pass's parameters), its key, and its unit, range and default as the docs' table writes
/// them (Markdown: `\|` is a '|'). A numeric range ("(0, 1e6]", "integer [1, 64]", a note
/// after ',' or ';') is what the parser accepts (io/scene_field_range.h); a default that is
/// a plain number is what the parser uses when the key is absent.
struct SceneField {
  std::string_view section, key, unit, range, default_text;
};

inline constexpr SceneField kSceneFields[] = {
    {"", "name", "", "letters, digits, `-`, `_`; not empty", "the file's stem"},
    {"", "description", "", "any string", "`\"\"`"},
    {"", "volume", "", "object, see below", "required"},
    {"", "isovalue", "the volume's units", "[-1e30, 1e30]", "required"},
    {"", "inside", "", "`\"above\"`, `\"below\"`", "`\"above\"`"},
    {"", "servo", "", "objects", "see below"},
    {"", "device", "", "objects", "see below"},
    {"", "script", "", "objects", "see below"},
    {"", "engine", "", "objects", "see below"},
    {"", "edits", "", "objects", "see below"},
    {"", "outputs", "", "objects", "see below"},
    {"", "materials", "", "object, below", "none (one material)"},
    {"volume", "path", "", "a file or DICOM folder, not empty", "-"},
    {"volume", "synthetic", "", "`\"sphere\"`, `\"box\"`, `\"three-spheres\"`, `\"knot\"`", "-"},
    {"volume", "dims", "voxels", "3 integers, each in [2, 1024]", "[64, 64, 64]"},
    {"volume", "spacing_m", "m", "[1e-6, 0.1]", "0.001"},
    {"volume", "radius_vox", "voxels", "(0, 1e4]", "20"},
    {"volume", "attribution", "", "any", "-"},
    {"servo", "stiffness_n_per_m", "N/m", "(0, 1e6]", "800"},
    {"servo", "damping_n_s_per_m", "N s/m", "[0, 1e3]", "1.0"},
    {"servo", "plane_update_period", "ticks", "integer [1, 100000]", "5"},
    {"servo", "rate_hz", "Hz", "[10, 100000]", "1000"},
    {"servo", "force_limit_n", "N", "(0, 1000]", "3.3"},
    {"servo", "variant", "", "`\"robust\"`, `\"paper\"`", "`\"robust\"`"},
    {"servo", "intersection", "", "`\"linear\"`, `\"secant\"`, `\"bisection\"`", "`\"linear\"`"},
    {"servo", "intersection_steps", "", "integer [1, 64]", "4"},
    {"servo", "normal", "", "`\"samples\"`, `\"central\"`, `\"exact\"`", "`\"samples\"`"},
    {"servo", "force_shading", "", "true, false", "false"},
    {"servo", "recovery_time_s", "s", "[0, 10]", "0.02 (robust), 0 (paper)"},
    {"servo", "friction", "", "object, below", "none"},
    {"servo", "tool", "", "object, below", "see below"},
    {"servo", "allow_unstable_stiffness", "", "true, false", "false"},
    {"servo", "passivity_control", "", "true, false", "false"},
    {"servo.friction", "mu_s", "", "[0, 10]", "0"},
    {"servo.friction", "mu_d", "", "[0, 10]; at most `mu_s`", "0"},
    {"servo.friction", "viscous_n_s_per_m", "N s/m", "[0, 1e3]", "0"},
    {"servo.tool", "radius_mm", "mm", "[0, 100]", "0"},
    {"servo.tool", "point", "", "true, false", "false"},
    {"device", "mass_kg", "kg", "(0, 100]", "0.08"},
    {"device", "damping_n_s_per_m", "N s/m", "[0, 1e3]", "0.01"},
    {"device", "coulomb_friction_n", "N", "[0, 100]", "0"},
    {"device", "encoder_resolution_m", "m", "[0, 0.01]", "0"},
    {"device", "force_max_n", "N", "(0, 1000]", "10"},
    {"device", "hand_stiffness_n_per_m", "N/m", "(0, 1e5]", "300"},
    {"device", "hand_damping_n_s_per_m", "N s/m", "[0, 1e3]", "5"},
    {"device", "substeps", "", "integer [1, 10000]", "20"},
    {"device", "workspace_scale", "world m per device m", "(0, 1e3]", "1.0"},
    {"device", "allow_no_watchdog", "", "true, false", "false"},
    {"device", "link_max_force_n", "N", "(0, 1000]", "3.3"},
    {"device", "link_round_trip_ms", "ms", "[0, 1000]", "0"},
    {"device", "link_passivity_control", "", "true, false", "false"},
    {"script", "ray_origin_frac", "fractions of the volume box", "vector, each in [-2, 3]", "[0.5, 0.5, 1.2]"},
    {"script", "ray_direction", "", "vector, not zero", "[0, 0, -1]"},
    {"script", "stroke_direction", "", "vector; not zero when `stroke_length_m` > 0", "[1, 0, 0]"},
    {"script", "approach_distance_m", "m", "(0, 1]", "0.010"},
    {"script", "approach_speed_m_s", "m/s", "(0, 10]", "0.020"},
    {"script", "press_depth_m", "m", "[0, 1]", "0.008"},
    {"script", "press_speed_m_s", "m/s", "(0, 10]", "0.020"},
    {"script", "hold_s", "s", "[0, 3600]", "0.2"},
    {"script", "stroke_length_m", "m", "[0, 10]", "0.040"},
    {"script", "stroke_speed_m_s", "m/s", "(0, 10]", "0.040"},
    {"script", "rest_s", "s", "[0, 3600]", "0.1"},
    {"script", "lift_retrace", "", "true, false", "false"},
    {"script", "plan", "", "`\"ray\"`, `\"surface\"`", "`\"ray\"`"},
    {"script", "press_force_fraction", "fraction of `servo.force_limit_n`", "(0, 0.95]", "0.6"},
    {"engine", "passes", "", "non-empty array", "`[\"gradient\"]`"},
    {"engine", "mode", "", "`\"sparse\"`, `\"dense\"`", "`\"sparse\"`"},
    {"engine", "samples", "", "`\"fp32\"`, `\"fp16\"`, `\"unorm16\"`", "`\"fp32\"`"},
    {"edits", "brush", "", "a brush, below", "the brush defaults"},
    {"edits", "every_ticks", "ticks", "integer [1, 1e6]", "10"},
    {"edits", "button", "s", "array of `[t0, t1]`, 0 <= t0 < t1 <= 1e6, in order, not overlapping", "none"},
    {"edits", "timeline", "", "array of timed edits, below", "none"},
    {"edits", "history_limit_mib", "MiB", "[0, 1048576]", "256"},
    {"edits", "write_vdb", "", "true, false", "true"},
    {"edits", "write_nrrd", "", "true, false", "true"},
    {"edits", "write_stl", "", "true, false", "true"},
    {"edits.brush", "kind", "", "`\"add\"`, `\"carve\"`, `\"smooth\"`, `\"drill\"`", "`\"carve\"`"},
    {"edits.brush", "radius_mm", "mm", "(0, 1000]", "2"},
    {"edits.brush", "strength", "value units per application; smooth: a fraction", "[0, 1e30]; smooth: [0, 1]", "100"},
    {"edits.brush", "falloff", "fraction of the radius", "(0, 1]", "0.5"},
    {"edits.brush", "force_threshold_n", "N", "[0, 1000]", "1.0"},
    {"edits.brush", "rate", "value units per N s", "[0, 1e12]", "1000"},
    {"edits.brush", "removal_per_n_s", "fraction of \\|material - empty\\| per N s", "[0, 1e6]", "not set"},
    {"edits.brush", "density_scale", "value units", "(0, 1e30]", "\\|material - empty\\|"},
    {"edits.brush", "material", "value units", "[-1e30, 1e30]", "max(max value, tau) (inside above)"},
    {"edits.brush", "empty", "value units", "[-1e30, 1e30]", "the far outside end of the value range"},
    {"edits.timeline", "t_s", "s", "[0, 1e6]", "required"},
    {"edits.timeline", "at", "mm, physical frame", "vector, or `\"vhip\"`", "required"},
    {"edits.timeline", "duration_s", "s", "[0, 3600]", "0"},
    {"edits.timeline", "force_n", "N", "[0, 1000]", "the \\|F\\| rendered that tick"},
    {"outputs", "trace_csv", "", "true, false", "true"},
    {"outputs", "plots", "", "true, false", "true"},
    {"materials", "labels", "", "a label map (NIfTI, NRRD) or a `.seg.nrrd`, relative to the scene file", "none: a transfer function"},
    {"materials", "list", "", "array of 1 to 255 materials, below", "required"},
    {"materials.list", "name", "", "not empty, unique", "required"},
    {"materials.list", "label", "", "integer [1, 65535]", "required with a label map; `.seg.nrrd`: the segment of this name's"},
    {"materials.list", "range", "the volume's units", "`[lo, hi)`, lo < hi, not overlapping another's", "required with a transfer function"},
    {"materials.list", "stiffness_n_per_m", "N/m", "(0, 1e6]", "800"},
    {"materials.list", "mu_s", "", "[0, 10]", "0"},
    {"materials.list", "mu_d", "", "[0, 10]; at most `mu_s`", "0"},
    {"materials.list", "rate", "value units per N s", "[0, 1e12]", "the drill's (`edits.brush`)"},
    {"materials.list", "density_scale", "value units", "[0, 1e30]", "0"},
    {"materials.list", "color", "", "3 numbers, each in [0, 1]", "the segment's colour, else grey"},
    {"materials.list", "critical", "", "true, false", "false"},
    {"materials.list", "margin_mm", "mm", "[0, 100]", "0"},
    {"engine.passes.gaussian", "sigma_mm", "mm", "(0, 1000]", "required"},
    {"engine.passes.closing", "radius_mm", "mm", "[0, 1000]", "required"},
    {"engine.passes.brick_minmax", "halo", "voxels", "integer [0, 8]", "1"},
};

/// The keys of `section` in kSceneFields.
inline std::set<std::string> scene_keys(std::string_view section) {
  std::set<std::string> keys;
  for (const SceneField& f : kSceneFields)
    if (f.section == section) keys.emplace(f.key);
  return keys;
}

/// The field `key` of `section`, or nullptr.
inline const SceneField* scene_field(std::string_view section, std::string_view key) {
  for (const SceneField& f : kSceneFields)
    if (f.section == section && f.key == key) return &f;
  return nullptr;
}

}  // namespace isotouch::io
