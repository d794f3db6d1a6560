// scene.h - a scene file (JSON): volume, isovalue, servo, device, script, outputs.
#pragma once
#include <array>
#include <stdexcept>
#include <string>
#include <vector>

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

/// One engine pass as the scene lists it (engine::PassDesc without the engine's headers:
/// the scene library builds without Vulkan). Converted and checked with
/// engine::validate_passes by app::scene_passes (run_job.h).
struct PassSpec {
  std::string kind;       ///< "gaussian", "closing", "gradient", "brick_minmax"
  double sigma_mm = 0;    ///< gaussian: standard deviation [mm], > 0
  double radius_mm = 0;   ///< closing: structuring element half-width [mm], >= 0
  int halo = 1;           ///< brick_minmax: voxels added on each side of a brick, 0..8
};

/// How the scene's samples are computed and published (issue 8 items 3-5).
struct EngineSpec {
  /// Passes in order; the default is today's single gradient pass. Filters (gaussian,
  /// closing) come before "gradient", which is required (the servo reads its samples).
  std::vector<PassSpec> passes{PassSpec{"gradient"}};
  /// "sparse": passes on candidate bricks only, a bricked snapshot (engine/sparse_chain.h);
  /// "dense": every voxel, 16 B per voxel (engine/passes.h), kept for comparison.
  std::string mode = "sparse";
  /// Sample format of the published snapshot: "fp32" (16 B), "fp16" or "unorm16" (8 B,
  /// bricked only).
  std::string samples = "fp32";
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
  EngineSpec engine;         ///< the "engine" section (defaults: gradient only, sparse, fp32)
};

/// Parse and validate a scene file. Unknown keys are errors (they are usually typos).
/// @throws SceneError "FILE: field 'servo.stiffness_n_per_m': must be > 0, got -3".
Scene load_scene(const std::string& path);

/// Parse from text (fuzzing, tests); `path` is used in messages and for relative paths.
Scene parse_scene(const std::string& text, const std::string& path);

}  // namespace isotouch::app
