// scene.h - a scene file (JSON): volume, isovalue, servo, device, script, outputs.
#pragma once
#include <array>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/materials/material.h"
#include "isotouch/servo/hri.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"

namespace isotouch::io {

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
/// engine::validate_passes by run::scene_passes (run/scene_setup.h).
struct PassSpec {
  std::string kind;       ///< "gaussian", "closing", "gradient", "brick_minmax"
  double sigma_mm = 0;    ///< gaussian: standard deviation [mm], > 0
  double radius_mm = 0;   ///< closing: structuring element half-width [mm], >= 0
  int halo = 1;           ///< brick_minmax: voxels added on each side of a brick, 0..8
};

/// How the scene's samples are computed and published.
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

/// A brush as the scene gives it (session::Brush without the engine's headers). Units as
/// the scene writes them: mm, the volume's value units, N, s.
struct BrushSpec {
  std::string kind = "carve";      ///< "add", "carve", "smooth", "drill"
  double radius_mm = 2.0;          ///< > 0
  double strength = 100.0;         ///< add/carve: value units per application; smooth: [0, 1]
  double falloff = 0.5;            ///< soft edge as a fraction of the radius, (0, 1]
  double force_threshold_n = 1.0;  ///< drill: nothing is removed at or below this |F| [N]
  double rate = 1000.0;            ///< drill: value units removed per (N above the threshold) per s
  /// drill: the same in units that mean the same on every volume: the fraction of the
  /// brush's |material - empty| removed per (N above the threshold) per s at density
  /// factor 1 (0.01: 1 % of the range per N s). < 0 = not given ("rate" holds).
  double removal_per_n_s = -1;
  double density_scale = 0;        ///< drill: > 0, or 0 = session::default_targets' (|material - empty|)
  bool has_material = false, has_empty = false;
  double material = 0, empty = 0;  ///< target values; default session::default_targets'
  double force_n = -1;             ///< drill on the timeline: |F| [N]; < 0 = the |F| rendered that tick
};

/// One timed entry of edits.timeline.
struct TimedEdit {
  int index = 0;                  ///< position in the scene file's list (for messages)
  double t_s = 0;                 ///< applied after the render of tick ceil(t_s * rate) (run::edit_tick)
  std::string kind;               ///< a brush kind, or "undo" / "redo"
  bool at_vhip = false;           ///< "at": "vhip": the VHIP of each application's tick
  core::Vec3 at_m;               ///< else "at": [x, y, z] mm in the physical frame (trace.csv's), here in m
  BrushSpec brush;                ///< edits.brush with this entry's overrides
  double duration_s = 0;          ///< > 0: a stroke, one application every edits.every_ticks ticks over [t_s, t_s + duration_s)
};

/// The "edits" section: brush defaults, a timeline, the device button.
struct EditsSpec {
  bool present = false;               ///< the scene has an "edits" section
  BrushSpec brush;                    ///< defaults, and the button's brush
  int every_ticks = 10;               ///< servo ticks between two applications of a stroke / the button
  /// Intervals [t0, t1) [s] during which the device button is down; while it is down and
  /// the probe is in contact, `brush` is applied at the VHIP every `every_ticks` ticks (a
  /// drill with the |F| rendered that tick), one undo stroke per press.
  std::vector<std::array<double, 2>> button_down;
  std::vector<TimedEdit> timeline;    ///< sorted by t_s (stable: entries at one time keep their order)
  double history_limit_mib = 256.0;   ///< undo memory limit [MiB]
  bool write_vdb = true;              ///< write the edited volume as drilled.vdb
  bool write_nrrd = true;             ///< also as drilled.nrrd (ITK: 3D Slicer opens it)
  bool write_stl = true;              ///< write its isosurface as drilled.stl
};

/// device.workspace_scale's range [world m per device m]: below it a touch asks for the
/// force limit at once, above it the volume fits in a fraction of a millimetre of hand travel.
inline constexpr double kMinWorkspaceScale = 1e-4;
inline constexpr double kMaxWorkspaceScale = 10.0;

struct Scene {
  std::string file;          ///< the scene file as given
  std::string name;
  std::string description;
  std::string volume_path;   ///< resolved against the scene file's folder; empty if synthetic
  SyntheticSpec synthetic;   ///< used when volume_path is empty
  servo::HriParams hri;      ///< tau, inside, K, B, n, rate, force limit
  sim::SimDeviceParams device;
  /// device.workspace_scale: world [m] per device [m], in [kMinWorkspaceScale,
  /// kMaxWorkspaceScale]. The force is stiffness x the hand's travel, the probe's depth in
  /// the volume / workspace_scale.
  double workspace_scale = 1.0;
  /// device.allow_no_watchdog (default false): drive a report device whose capabilities say
  /// it has no watchdog (0 ms: its last force stays on if the host stops sending) instead of
  /// refusing it.
  bool allow_no_watchdog = false;
  /// device.link_max_force_n (default 3.3 N, the Touch's peak, the device behind a PlusServer):
  /// the peak force [N] a link's device is sent (`--haptic igtl:`, serve's TRANSFORM stream),
  /// whose device isotouch cannot ask. The servo's gate clamps to min(servo.force_limit_n,
  /// this) and limits the force's rate to that over 2 ms.
  double link_max_force_n = 3.3;
  /// device.link_round_trip_ms (default 0): a link's round trip beyond its hold [s here]
  /// (`--haptic igtl:`): the peer's transport and its own loop, which an OpenIGTLink stream
  /// cannot measure. The stiffness check simulates the stream's hold (one measured period)
  /// plus this (sim::link_k_max).
  double link_round_trip_s = 0;
  /// device.link_passivity_control (default false): the link's device end (the peer) runs
  /// the time-domain passivity controller on its own loop (as tests/igtl_hand_peer.cpp and
  /// sim/linked_contact.h do; isotouch cannot put it there nor see it). With it the stiffness
  /// check of `--haptic igtl:` takes the bound with the controller.
  bool link_passivity_control = false;
  /// servo.allow_unstable_stiffness (default false): run a servo.stiffness_n_per_m above
  /// the Colgate-Schenkel bound 2 (b - |B|) / T (b: device + hand damping [N s/m], B: servo
  /// damping [N s/m], T: 1 / rate_hz [s]). Without it such a scene is refused; with it the
  /// run warns and reports the bound (stability experiments).
  bool allow_unstable_stiffness = false;
  /// servo.passivity_control (default false): the live servo's passivity controller adds the
  /// damping that keeps the energy its force hands the user at or below what the user put in
  /// (servo/live_passivity.h; docs/haptics.md says where it helps and where it does not).
  bool passivity_control = false;
  /// servo.tool.point (default false): the button's carve or drill brush is felt as a
  /// point, not as the spherical tool of the brush's radius (for comparison with the burr).
  bool point_probe = false;
  /// The tool's radius came from the button's carve or drill brush (edits.brush with
  /// edits.button intervals, servo.tool.radius_mm not given): what touches is what cuts.
  bool tool_from_brush = false;
  sim::ScriptParams script;
  bool write_trace = true;
  bool draw_plots = true;
  EngineSpec engine;         ///< the "engine" section (defaults: gradient only, sparse, fp32)
  EditsSpec edits;           ///< the "edits" section (present = false without one)
  /// The "materials" section (present = false without one: the scan is one material);
  /// labels_path resolved against the scene file's folder. Read by materials::load_label_volume.
  materials::MaterialsSpec materials;
};

/// Parse and validate a scene file. Unknown keys are errors (they are usually typos).
/// @throws SceneError "FILE: field 'servo.stiffness_n_per_m': must be > 0, got -3".
Scene load_scene(const std::string& path);

/// Parse from text (fuzzing, tests); `path` is used in messages and for relative paths.
Scene parse_scene(const std::string& text, const std::string& path);

}  // namespace isotouch::io
