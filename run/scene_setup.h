// scene_setup.h - a scene made ready to run: volume, engine samples, script, servo
// parameters and the edit session; the scene's brushes and passes as engine types.
#pragma once
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/session/edit_session.h"
#include "isotouch/servo/hri.h"
#include "isotouch/session/live_field.h"
#include "isotouch/io/mesh_units.h"
#include "isotouch/io/record.h"
#include "isotouch/run/run_metrics.h"
#include "isotouch/io/scene.h"
#include "isotouch/servo/workspace.h"
#include "isotouch/sim/script.h"

// Held by pointer here: the Vulkan context (engine/vk_context.h, which includes Vulkan's
// headers), the labelled scene's materials (materials/, session/material_cut.h). A source
// that uses them includes their headers; this one stays on the public API (api/isotouch.h).
namespace isotouch::engine {
class VulkanContext;
}
namespace isotouch::materials {
class CriticalDistance;
struct LabelVolume;
}  // namespace isotouch::materials
namespace isotouch::session {
struct MaterialCut;
}

namespace isotouch::run {

/// The device choice (--device or $ISOTOUCH_DEVICE) that runs the engine, the brushes and the
/// pictures on the CPU, no Vulkan context: the engine chain on up to 8 hardware threads
/// (engine::hardware_threads; bit for bit the one-thread reference), the brushes and the
/// pictures by the one-thread CPU references. A run with no device asked for falls back to
/// it when no Vulkan device can be opened, and says so.
inline constexpr const char* kCpuDevice = "cpu";
/// True if `device` asks for the CPU backend (kCpuDevice).
bool is_cpu_device(const std::string& device);

struct RunOptions {
  std::string out_dir;                 ///< where trace.csv, summary.json, report.md go
  std::string device;                  ///< Vulkan device choice (see ContextOptions), or kCpuDevice
  bool progress = true;                ///< progress line on stderr
  std::uint64_t max_binding_bytes = 0; ///< test hook: smaller storage-binding limit
  /// `run --record FILE`: also write the recording (io/record.h: every device input,
  /// button and edit with its tick and time, and the forces) to this file; "" = none.
  std::string record_path;
  /// `run --mesh-units`: the unit of drilled.stl's coordinates (physical frame, LPS).
  io::MeshUnits mesh_units = io::MeshUnits::kMillimetre;
};

/// The scene's pass list as engine passes (engine.passes), checked with
/// engine::validate_passes. @throws SceneError "FILE: field 'engine.passes': pass 1 (...): ...".
std::vector<engine::PassDesc> scene_passes(const io::Scene& scene);
/// The engine brush of a scene brush: centre grid-world [m], application time dt_s [s],
/// drill force |F| [N]; targets from `defaults` (session::default_targets) unless the scene
/// sets them.
session::Brush make_brush(const io::BrushSpec& b, const session::BrushTargets& defaults, const core::Vec3& centre_m,
                          double dt_s, double force_n);
/// The drill's per-material cut of a labelled scene: `lv`'s ids and, per material, its rate,
/// density scale and critical flag (for session::Sculptor::set_material_cut).
std::shared_ptr<const session::MaterialCut> material_cut(const materials::LabelVolume& lv);
/// The drill's rate in value units per (N s): "rate" as given, or "removal_per_n_s" times
/// the targets' |material - empty|.
double drill_rate(const io::BrushSpec& b, const session::BrushTargets& t);
/// How far past the spherical tool's surface a brush at the VHIP reaches [m]: half the
/// largest voxel spacing, so the brush's full-strength core covers the surface the burr
/// touches (which lies within a cell of it) and the channel stays the burr's width.
double tool_brush_margin_m(const engine::Volume& vol);
/// A brush applied at the VHIP: with a spherical tool (servo.tool.radius_mm > 0, or the
/// carve or drill brush's radius by default) the VHIP is the tool's centre and the brush
/// takes the tool's radius plus tool_brush_margin_m, so it removes what the burr's surface
/// touches; a point tool keeps the scene's radius.
io::BrushSpec brush_at_tool(const io::Scene& scene, const engine::Volume& vol, const io::BrushSpec& b);

/// The scene's engine.samples as a core::SampleFormat.
core::SampleFormat scene_sample_format(const io::Scene& scene);

/// Everything the servo loop of a scene needs, built the same way for `isotouch run` and
/// `isotouch replay` (which rebuilds the exact pipeline from a recording's scene file).
/// Frames: grid-world [m] for every point (core::Grid), device [m] through world_T_device.
struct SceneSetup {
  engine::Volume volume;                         ///< as loaded, before any edit
  session::LiveFieldOptions live;                 ///< passes, isosurface, background, format
  servo::HriParams hri;                          ///< the renderer's parameters (scene.hri)
  servo::WorkspaceTransform world_T_device;      ///< world = translation + scale * device
  sim::TouchScript script;                     ///< the scripted hand (cast on `truth`)
  /// The first published snapshot (version 1). With edits: the session::EditSession's (LiveField
  /// version 1 = run_sparse_cpu, bit-identical to the GPU sparse chain); without edits:
  /// the GPU chain's output, as before edits existed.
  std::shared_ptr<const core::SampleField> first;
  /// Dense fp32 samples of the scene's passes on the unedited volume (CPU reference): the
  /// script is cast on it and the surface error measured against it.
  std::shared_ptr<const core::SampleField> truth;
  std::unique_ptr<engine::VulkanContext> vk;     ///< the Vulkan context (engine, brushes, pictures); null on the CPU backend
  /// The device the run's outputs use: RunOptions::device, or kCpuDevice on the CPU backend
  /// (asked for, or fallen back to).
  std::string device;
  /// The edit pipeline (brushes on the GPU when there is a device, else the CPU reference)
  /// when the scene has an "edits" section, else null. Built from a copy of `volume`.
  std::unique_ptr<session::EditSession> session;
  RunMetrics metrics;                            ///< the volume and engine figures (what run_scene reports)
  /// Labelled scenes (a "materials" section): the drill's per-material cut, given to the
  /// edit session's Sculptor (null without materials: one material, today's path).
  std::shared_ptr<const session::MaterialCut> cut;
  /// Labelled scenes: the materials on the volume's grid as loaded (their names, label values
  /// and colours: the edited label map drilled.seg.nrrd). Null without materials.
  std::shared_ptr<const materials::LabelVolume> labels;
  /// One per critical material (empty when none is): its name, id, margin and the distance
  /// to its own voxels, so that each is warned about at its own margin_mm.
  struct CriticalStructure {
    std::string name;
    std::uint8_t id = 0;      ///< its id in cut->ids
    double margin_m = 0;      ///< the warning distance [m] (its margin_mm)
    std::shared_ptr<const materials::CriticalDistance> distance;
  };
  std::vector<CriticalStructure> critical;
  SceneSetup();
  SceneSetup(SceneSetup&&) noexcept;
  SceneSetup& operator=(SceneSetup&&) noexcept;
  ~SceneSetup();
};

/// Loads the scene's volume, runs its engine (GPU chain + CPU reference, the report's
/// figures), builds the script and, with edits, the session::EditSession. run_scene starts with it.
/// @throws as run_scene.
SceneSetup setup_scene(const io::Scene& scene, const RunOptions& options, std::ostream& log);
/// The same on `volume` (already in memory: scene.volume_path is not read), e.g. a volume
/// made in Python. @throws as run_scene.
SceneSetup setup_scene(const io::Scene& scene, engine::Volume volume, const RunOptions& options, std::ostream& log);

/// The tick after whose render an event at time t_s [s] is applied: the first tick k with
/// k / rate_hz >= t_s (to 1e-9 tick).
long edit_tick(double t_s, double rate_hz);

/// The header of a recording of `scene` (format 3 once a LiveSession streams it): the scene
/// file's path and text, the servo rate and the CRC-32 of the unedited volume.
io::Recording recording_header(const io::Scene& scene, const SceneSetup& setup);

}  // namespace isotouch::run
