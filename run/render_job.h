// render_job.h - what `isotouch render` runs: a scene's isosurface ray-cast to a PNG (GPU or
// the CPU reference), with the probe of the scene's run at one time or the run's path.
#pragma once
#include <optional>
#include <string>

#include "isotouch/engine/raycast.h"

namespace isotouch::run {

/// What `isotouch render` draws: a scene's isosurface from an orbit camera, optionally with
/// the probe of its run at one time (--time) or the run report's path picture (--path).
struct RenderOptions {
  std::string up, front;  ///< physical axes x, -x, ... (LPS); empty: the volume's default (default_camera)
  std::string scene;      ///< scene file
  std::string out;        ///< PNG to write; "" = <scene name>.png; "-" = standard output
  int width = 640, height = 640;  ///< [pixels]
  engine::OrbitCamera cam;
  /// Aim at the scan's box, not the object's (--frame-scan: one camera for volumes on one grid).
  bool frame_scan = false;
  std::optional<double> time_s;
  std::string trace;
  std::string clip_axis;
  double clip_at = 0.5;
  bool no_skip = false;
  bool cpu = false;
  bool path = false;
  float step = 0.5f;
};

/// Loads the scene and its volume, runs the scene first when --time or --path needs its trace
/// (unless `trace` names one), renders and writes the PNG atomically; prints one line about it.
/// @return 0. @throws std::runtime_error (bad axis, picture too large for the device's binding
/// limit, Vulkan set-up), SceneError / VolumeError naming the file.
int run_render(const RenderOptions& options, const std::string& device);

}  // namespace isotouch::run
