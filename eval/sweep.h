// sweep.h - scenes with a recorded stroke, replayed through any renderer configuration.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/servo/renderer.h"
#include "isotouch/eval/shapes.h"

namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch::eval {

/// A scene prepared for sweeps: samples, truth (synthetic) or a reference (CT), and the
/// HIP path of one scripted stroke, recorded once so every configuration replays the
/// same HIP positions (like HAPI's playback device).
struct SweepScene {
  std::string name;
  std::string description;
  std::shared_ptr<const core::SampleField> field;
  std::unique_ptr<Shape> truth;   ///< null for the real CTs
  double tau = 0;
  core::InsideIs inside = core::InsideIs::kAbove;
  double rate_hz = 1000;
  double stiffness_n_per_m = 800;
  std::vector<core::Vec3> hip;           ///< HIP per tick, world [m]
  std::vector<servo::HriTick> reference;  ///< CT only: the offline reference per tick
  double voxel_m = 1e-3;                  ///< smallest spacing
  std::size_t slide_begin = 0, slide_end = 0;  ///< ticks that slide on the surface (prescribed paths)
};

/// Scene names: sphere, box, three-spheres, knot (synthetic), head, chest (the CTs of
/// scenes/head.json and scenes/chest.json), or a path to a scene JSON file.
/// The stroke is recorded with the reference renderer (HRI, n = 1, 40 bisection steps,
/// exact trilinear gradient) driving the simulated device; for CTs the same reference,
/// replayed on the recorded path, is the truth. Samples come from the Vulkan gradient
/// pass when `vk` is given, else from the CPU reference (bit-identical).
/// `tau`, when given, replaces a scene file's isovalue (volume units) before anything is
/// sampled or recorded: the stroke and the offline reference are those of that isosurface.
/// The exact shapes' truth belongs to their own isovalue: std::invalid_argument for them.
SweepScene prepare_sweep_scene(const std::string& name, engine::VulkanContext* vk, std::ostream& log,
                               std::optional<double> tau = std::nullopt);

/// The reference renderer parameters for a scene (see prepare_sweep_scene).
servo::HriParams reference_params(const SweepScene& s);

struct Playback {
  std::vector<servo::HriTick> ticks;
  std::vector<std::int64_t> tick_ns;  ///< wall time of each Renderer::tick [ns]
};
/// Replay the recorded HIP path through `r` (reset first).
Playback playback(servo::Renderer& r, const SweepScene& s);
/// The same on another snapshot of the scene's samples (e.g. a bricked or compact one).
Playback playback(servo::Renderer& r, const SweepScene& s, const core::SampleField& field);

/// One published snapshot of a sweep scene's samples.
struct SnapshotVariant {
  std::string name;  ///< "fp32 dense", "fp32 bricked", "fp16 bricked", "unorm16 bricked"
  std::shared_ptr<const core::SampleField> field;
  std::uint64_t bytes = 0;  ///< core::snapshot_bytes: what the snapshot holds in memory [B]
  /// Host time to build it from the dense fp32 samples (core::bricked_input_from_dense +
  /// core::make_bricked_field; 0 for the dense one), median of 3 [ms], this machine.
  double build_ms = 0;
  std::size_t bricks_total = 0, bricks_active = 0;  ///< 0 for the dense one
};
/// The scene's dense fp32 snapshot (s.field) and its bricked fp32, fp16 and unorm16 versions.
std::vector<SnapshotVariant> snapshot_variants(const SweepScene& s);

/// One snapshot's HRI run against the dense fp32 one's, along the same recorded HIP path.
struct FormatFigures {
  long contact_ticks = 0;          ///< ticks in contact on this snapshot
  long contact_ticks_dense = 0;    ///< ... on the dense fp32 snapshot
  /// Distance of the VHIP from the isosurface of the dense fp32 samples (surface_distance.h),
  /// over this snapshot's contact ticks [m]: for the dense snapshot the servo's own error,
  /// for the others that error plus what the storage costs.
  double surface_err_rms_m = 0, surface_err_max_m = 0;
  /// |F - F_dense fp32| over the ticks where either run is in contact [N].
  double force_diff_rms_n = 0, force_diff_max_n = 0;
  long contact_mismatch_ticks = 0;  ///< ticks in contact on one snapshot and not the other
  double mean_force_dense_n = 0;    ///< mean |F| of the dense run over its contact ticks [N] (a scale)
};
FormatFigures compare_to_dense(const SweepScene& s, const Playback& p, const Playback& dense);

/// Errors of one configuration against the truth (synthetic) or the reference (CT).
struct ErrorFigures {
  double tick_ns_mean = 0, tick_ns_p99 = 0;
  /// Distance of the VHIP from the true surface, RMS over contact ticks: the exact shape
  /// (synthetic) or the true distance to the trilinear isosurface (CTs, surface_distance.h).
  double surface_err_rms_m = 0;
  double angle_err_rms_deg = 0;  ///< angle between the force and the true normal
  double force_err_rms_n = 0;    ///< |F - F_god-object| (synthetic) or |F - F_reference| (CT)
  double max_force_step_n = 0;   ///< largest |F_k - F_k-1| over the stroke
  double max_force_step_slide_n = 0;  ///< ... over the sliding ticks only (prescribed paths)
  long contact_ticks = 0;
  /// Contact lost while the HIP is more than half a voxel inside the object (truth: exact
  /// shape depth, or the reference renderer's penetration on CTs): a pop-through.
  long pop_throughs = 0;
};
ErrorFigures measure(const SweepScene& s, const Playback& p);

/// Total time of `reps` replays after `warmup` ones, each divided by the tick count;
/// returns the median [ns per tick]. `cancel` (if given) is looked at between replays: once
/// set, no further replay starts and the result is NaN (a caller that was interrupted).
double median_ns_per_tick(servo::Renderer& r, const SweepScene& s, int warmup, int reps,
                          const std::atomic<bool>* cancel = nullptr);
/// The same on another snapshot of the scene's samples.
double median_ns_per_tick(servo::Renderer& r, const SweepScene& s, const core::SampleField& field, int warmup,
                          int reps, const std::atomic<bool>* cancel = nullptr);

}  // namespace isotouch::eval
