// run_job.h - the main job: volume -> GPU samples -> HRI servo on a scripted stroke.
#pragma once
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "headless.h"
#include "scene.h"

namespace isotouch::app {

struct RunOptions {
  std::string out_dir;                 ///< where trace.csv, summary.json, report.md go
  std::string device;                  ///< Vulkan device choice (see ContextOptions)
  bool progress = true;                ///< progress line on stderr
  std::uint64_t max_binding_bytes = 0; ///< test hook: smaller storage-binding limit
};

/// Figures of one run (also written to summary.json).
struct RunMetrics {
  std::string volume_path;
  std::array<int, 3> dims{};
  servo::Vec3 spacing_m;
  std::string gpu_device;
  std::string gpu_device_type;
  double gpu_gradient_ms = 0, gpu_upload_ms = 0, gpu_download_ms = 0, gpu_submit_wall_ms = 0;
  int gpu_slabs = 0;
  bool gpu_timestamps = false;
  double cpu_gradient_ms = 0;
  double max_abs_diff = 0, max_rel_diff = 0, max_abs_diff_xyz[3] = {0, 0, 0};
  long ticks = 0;
  double tick_ns_median = 0, tick_ns_p99 = 0, tick_ns_max = 0, tick_ns_mean = 0;
  long contact_ticks = 0, plane_updates = 0, saturated_ticks = 0, fault_ticks = 0;
  double max_force_n = 0, max_penetration_m = 0, mean_contact_force_n = 0;
  double surface_err_rms_m = 0, surface_err_max_m = 0;
  bool plots_drawn = false;
  std::string plot_note;
};

/// Run one scene end to end and write its outputs into options.out_dir.
/// @throws engine::VolumeError, SceneError, std::runtime_error with a clear reason.
RunMetrics run_scene(const Scene& scene, const RunOptions& options, std::ostream& log);

}  // namespace isotouch::app
