// scene.h - a scene file (JSON): volume, isovalue, servo, device, script, outputs.
#pragma once
#include <array>
#include <stdexcept>
#include <string>

#include "hri.h"
#include "script.h"
#include "sim_device.h"

namespace isotouch::app {

/// A scene problem. what() names the file, the field and the value.
struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct SyntheticSpec {
  std::string kind;                     ///< "sphere", or the fixed scenes "box", "three-spheres", "knot"
  std::array<int, 3> dims{64, 64, 64};  ///< voxels
  double spacing_m = 1e-3;              ///< isotropic voxel size [m]
  double radius_vox = 20;               ///< sphere radius [voxels]
};

struct Scene {
  std::string file;          ///< the scene file as given
  std::string name;
  std::string description;
  std::string volume_path;   ///< resolved against the scene file's folder; empty if synthetic
  SyntheticSpec synthetic;   ///< used when volume_path is empty
  servo::HriParams hri;      ///< tau, inside, K, B, n, rate, force limit
  servo::SimDeviceParams device;
  double workspace_scale = 1.0;  ///< world [m] per device [m]
  servo::ScriptParams script;
  bool write_trace = true;
  bool draw_plots = true;
};

/// Parse and validate a scene file. Unknown keys are errors (they are usually typos).
/// @throws SceneError "FILE: field 'servo.stiffness_n_per_m': must be > 0, got -3".
Scene load_scene(const std::string& path);

/// Parse from text (fuzzing, tests); `path` is used in messages and for relative paths.
Scene parse_scene(const std::string& text, const std::string& path);

}  // namespace isotouch::app
