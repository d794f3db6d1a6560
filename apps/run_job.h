// run_job.h - the main job: volume -> GPU samples -> HRI servo on a scripted stroke.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "brick_field.h"
#include "headless.h"
#include "passes.h"
#include "scene.h"

namespace isotouch::app {

struct RunOptions {
  std::string out_dir;                 ///< where trace.csv, summary.json, report.md go
  std::string device;                  ///< Vulkan device choice (see ContextOptions)
  bool progress = true;                ///< progress line on stderr
  std::uint64_t max_binding_bytes = 0; ///< test hook: smaller storage-binding limit
  /// `run --record FILE`: also write the recording (apps/record.h: every device input,
  /// button and edit with its tick and time, and the forces) to this file; "" = none.
  std::string record_path;
};

/// The scene's pass list as engine passes (engine.passes), checked with
/// engine::validate_passes. @throws SceneError "FILE: field 'engine.passes': pass 1 (...): ...".
std::vector<engine::PassDesc> scene_passes(const Scene& scene);
/// The scene's engine.samples as a core::SampleFormat.
core::SampleFormat scene_sample_format(const Scene& scene);

/// One pass (dense) or stage (sparse) as it ran.
struct PassFigure {
  std::string label;   ///< engine::PassTiming::label
  double ms = -1;      ///< GPU: device time (timestamps; -1 if none); CPU: wall time [ms]
  int dispatches = 0;  ///< GPU dispatches; 0 on the CPU
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
  /// Largest change of |F| [N] between two consecutive ticks that are both in contact.
  double max_force_step_n = 0;
  double max_force_step_t_s = 0;  ///< time of the second tick of that step [s]
  /// Largest |F| [N] on a contact tick whose next tick has no contact while the HIP (at
  /// that next tick) is still inside the object (trilinear field at the HIP, the scene's
  /// isovalue and inside): the force drop that max_force_step_n cannot see.
  double max_release_step_n = 0;
  double max_release_step_t_s = 0;  ///< time of the tick with no contact [s]
  /// Largest change of |F| [N] between any two consecutive ticks, in contact or not.
  double max_any_step_n = 0;
  double max_any_step_t_s = 0;  ///< time of the second tick of that step [s]
  /// True distance [m] of the VHIP from the trilinear isosurface over the contact ticks
  /// (apps/surface_distance.h: bounded search, accurate to 1e-3 voxel), RMS and max over
  /// the ticks where a surface was found within surface_search_radius_m.
  /// Both 0 (and null in summary.json) when no contact tick found a surface.
  double surface_err_rms_m = 0, surface_err_max_m = 0;
  long surface_err_not_found_ticks = 0;  ///< contact ticks with no surface within the radius
  double surface_search_radius_m = 0;
  /// The old first-order estimate |f - tau| / |grad f| (unbounded where the field is
  /// flat), kept beside the true distance to show the difference.
  double first_order_err_rms_m = 0, first_order_err_max_m = 0;
  std::string orientation;               ///< e.g. "LPS" (engine::Volume::orientation)
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major D
  std::size_t nan_voxels = 0, inf_voxels = 0;
  bool plots_drawn = false;
  std::string plot_note;
  /// surface.png (issue 10): the isosurface, the HIP path and the contact points coloured
  /// by |F| (app::render_run_picture); caption, or why it was not drawn.
  bool picture_drawn = false;
  std::string picture_note;

  // Engine (issue 8 items 3-5): what computed the published samples.
  std::string engine_mode;     ///< "dense" or "sparse" (the scene's engine.mode)
  std::string engine_ran;      ///< what actually computed the published snapshot (GPU)
  std::string engine_fallback; ///< why the sparse GPU chain was not used; empty if it was (or mode is dense)
  std::string reference_ran;   ///< what computed the CPU reference
  std::string sample_format;   ///< "fp32", "fp16", "unorm16"
  std::vector<engine::PassDesc> passes;  ///< the scene's list, as run
  std::vector<PassFigure> gpu_passes, cpu_passes;
  std::string engine_describe; ///< PassChain/SparseChain::describe(): pipelines, buffers created and left out
  std::size_t bricks_total = 0, bricks_candidates = 0, bricks_active = 0;  ///< sparse only
  std::uint64_t snapshot_bytes = 0;    ///< bytes of the published snapshot
  std::uint64_t dense_fp32_bytes = 0;  ///< voxels * 16: the dense fp32 snapshot
  double publish_ms = 0;               ///< host time building the published snapshot (sparse) [ms]
  /// Angle [deg] between the force directions of two consecutive contact ticks, RMS and max:
  /// how rough the rendered surface feels (noise in the data shows here).
  double force_dir_step_rms_deg = 0, force_dir_step_max_deg = 0;
  /// With filters in the pass list: distance [m] of the VHIP from the isosurface of the
  /// unfiltered data (gradient only), RMS and max over the contact ticks with a surface
  /// found: what smoothing moves the felt surface away from the data. has_unfiltered false
  /// without filters.
  bool has_unfiltered = false;
  double unfiltered_err_rms_m = 0, unfiltered_err_max_m = 0;
};

/// Run one scene end to end and write its outputs into options.out_dir.
/// @throws engine::VolumeError, SceneError, std::runtime_error with a clear reason.
RunMetrics run_scene(const Scene& scene, const RunOptions& options, std::ostream& log);

}  // namespace isotouch::app
