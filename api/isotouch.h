// isotouch.h - the public API: what a program that embeds isotouch (a surgical simulator, an
// experiment driver, a Python module) includes. One header, read in one sitting; it names the
// library headers an embedding program uses and adds a few small conveniences on top of them.
// Installed as <PREFIX>/include/isotouch/isotouch.h; link isotouch::isotouch
// (find_package(isotouch CONFIG REQUIRED); pkg-config: docs/library.md). Tour: docs/library.md.
//
// The steps of an embedding program, in order, and who does each:
//   1. load a volume          isotouch::load_volume(path) -> engine::Volume          (io/vdb_io.h)
//   2. build the engine       a scene file: io::load_scene + run::setup_scene        (run/scene_setup.h)
//                             or a volume alone: make_edit_session(volume, field_options(volume, iso))
//   3. a renderer             servo::HriRenderer(hri_params(iso))                   (servo/hri.h)
//   4. a device               SimulatedHand (simulated), or run::open_haptic_device  (run/haptic_device.h:
//                             "sim", "null", "playback:FILE", "hid:VID:PID", "emu:SOCKET")
//   5. the live session       session::LiveSession(edits, buffer, renderer, device, config)
//                             start(), observe(), submit(), stats(), stop()          (session/live_session.h)
//      or 2, 3 and 5 owned together: session::Session::open(volume, options),
//                             attach(device, config), live()->start()                 (session/session.h)
//   6. record and replay      LiveSessionConfig::record_path; io::load_recording;   (io/record.h,
//                             run::replay_recording (scene-based sessions)           run/replay.h)
//
// Frames and units everywhere (core/grid.h, engine/volume.h):
//   - index: voxel (i, j, k), x fastest; voxel arrays are float32, x fastest, then y, then z,
//     in the file's value units (HU for CT);
//   - grid-world [m]: origin + index * spacing; every point the renderer, the brushes and
//     LiveSession::observe() use (HIP, VHIP, brush centres) is in this frame;
//   - physical [m]: the file's frame (ITK's LPS): origin + D (spacing * index), D the
//     direction matrix; engine::Volume::to_physical / to_grid convert; report points to a user
//     in it;
//   - device [m]: world = translation + scale * device (servo::WorkspaceTransform).
//   Forces are in newtons, in grid-world axes (= device axes: the map has no rotation;
//   engine::Volume::direction_apply turns them physical); times in s.
//
// Errors: bad input throws an exception whose what() names the file, the field and the value
// (engine::VolumeError, io::SceneError, io::RecordingError, session::BrushError,
// std::invalid_argument for a bad config); set-up that may legitimately fail (no Vulkan
// device) returns engine::Result with the reason. The library writes nothing to stdout; a
// few notes go to stderr (which series of a DICOM folder was taken).
//
// This header includes none of the engine's Vulkan headers (engine/vk_context.h: include it
// for a GPU engine) nor the run job's internals (run/names.h, the report and SDK devices).
// Internal (installed because other headers include them, but not an API to code
// against; they change without notice): the engine's Vulkan passes and resources
// (engine/vk_resources.h, passes.h, sparse_*.h, gradient_pass.h, raycast.h; of
// engine/vk_context.h only VulkanContext::create and ContextOptions), the sparse and brick
// internals (core/brick_field.h, session/live_gpu.h, engine/pool_recycler.h), the servo's
// codecs and threads (servo/hid_report.h, report_device.h, socket_link.h, spsc_ring.h,
// latest_value.h), the run job's pieces (run/*.h other than scene_setup.h, haptic_device.h,
// replay.h, run_scene.h), bench/, service/, eval/, and every `*_names.h`.
#pragma once
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <utility>

#include "isotouch/version.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"
#include "isotouch/engine/volume.h"
#include "isotouch/io/record.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/run/haptic_device.h"
#include "isotouch/run/replay.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/servo/workspace.h"
#include "isotouch/session/brush.h"
#include "isotouch/session/edit_session.h"
#include "isotouch/session/live_field.h"
#include "isotouch/session/live_session.h"
#include "isotouch/session/session.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"
#include "isotouch/sim/sim_device_io.h"

// The Vulkan context is named by pointer only: a program that runs the engine on a GPU
// includes "isotouch/engine/vk_context.h" (VulkanContext::create, ContextOptions; it brings
// Vulkan's headers, about 16,000 lines, that a CPU-only program does not need).
namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch {

// ---- 1. Volumes ---------------------------------------------------------------------------

/// Loads a volume: MetaImage (.mhd/.mha), NRRD (.nrrd/.nhdr), NIfTI (.nii, .nii.gz), a DICOM
/// series folder, or OpenVDB (.vdb). Voxels float32 (index frame, x fastest) in the file's
/// units; `grid` gives the spacing and origin [m], `direction` the physical frame.
/// @throws engine::VolumeError (io::VdbError for a .vdb) naming the file and what is wrong with it.
inline engine::Volume load_volume(const std::string& path) { return io::load_any_volume(path); }

// ---- 2. The engine: samples (value + gradient) the servo reads -----------------------------

/// The engine's settings for a volume without a scene file: the passes (default: the
/// gradient alone), the isosurface `isovalue` [value units] with the object on the side
/// `inside`, and the published background (outside the grid): a value outside the object.
inline session::LiveFieldOptions field_options(const engine::Volume& volume, double isovalue,
                                               core::InsideIs inside = core::InsideIs::kAbove) {
  session::LiveFieldOptions o;
  o.iso = core::Isosurface{isovalue, inside};
  o.background = float(o.iso.outside_value(volume.min_value, volume.max_value));
  return o;
}

/// The edited volume and its published snapshots: runs the engine passes once (the first
/// snapshot, version 1: EditSession::current(), a core::SampleField of Sample{value, gx, gy,
/// gz} per voxel, bricked) and applies edits afterwards. `vk` null: the CPU engine and CPU
/// brushes (bit for bit the Vulkan ones); else the brushes and large updates run on that
/// device (engine::VulkanContext::create, isotouch/engine/vk_context.h). `history_limit_mib`: the undo memory [MiB].
/// @throws engine::VolumeError, std::invalid_argument (bad passes or options).
inline std::unique_ptr<session::EditSession> make_edit_session(engine::Volume volume,
                                                               const session::LiveFieldOptions& options,
                                                               engine::VulkanContext* vk = nullptr,
                                                               double history_limit_mib = 256.0) {
  return std::make_unique<session::EditSession>(std::move(volume), vk, options, history_limit_mib);
}

// ---- 3. The renderer --------------------------------------------------------------------

/// HRI's parameters for the isosurface `isovalue` [value units], object on the side
/// `inside`, at `rate_hz`; the rest (stiffness 800 N/m, force limit 3.3 N, robust variant)
/// as servo::HriParams documents them. The renderer: servo::HriRenderer(hri_params(...)).
inline servo::HriParams hri_params(double isovalue, core::InsideIs inside = core::InsideIs::kAbove,
                                   double rate_hz = 1000.0) {
  servo::HriParams p;
  p.tau = isovalue;
  p.inside = inside;
  p.rate_hz = rate_hz;
  return p;
}

// ---- 4. A simulated device ----------------------------------------------------------------

/// A simulated device (a point mass, sim::SimDevice) pulled by a scripted hand: the hand
/// approaches the isosurface along a ray, presses in, strokes along it and lifts
/// (sim::ScriptParams: the ray's origin as fractions of the volume box, its direction, the
/// stroke's; distances [m], speeds [m/s], times [s]); looped. `io` is what the live session
/// drives (servo::HapticDeviceIO). The device starts where the hand starts.
/// Not copyable or movable (`io` refers to `device` and `script`): hold it by unique_ptr.
struct SimulatedHand {
  /// @throws std::runtime_error naming the ray when it never meets the isosurface of
  /// `field` (the renderer's `hri.tau`, `hri.inside`) or starts inside it.
  SimulatedHand(const core::SampleField& field, const servo::HriParams& hri, const sim::ScriptParams& script_params,
                const servo::WorkspaceTransform& world_T_device, const sim::SimDeviceParams& device_params = {})
      : script(sim::make_touch_script(field, hri, script_params)),
        device(device_params, world_T_device.to_device(script.waypoints.front().pos_m)),
        io(device, script, 1.0 / hri.rate_hz, world_T_device) {}
  SimulatedHand(const SimulatedHand&) = delete;
  SimulatedHand& operator=(const SimulatedHand&) = delete;

  sim::TouchScript script;  ///< the hand's target over time, grid-world [m]
  sim::SimDevice device;    ///< the end effector, device [m]
  sim::SimDeviceIO io;      ///< the device interface the servo reads and writes
};

// ---- 5. The live session ------------------------------------------------------------------

/// The servo settings of an embedding program that is not the only real-time load of its
/// machine (a test, an analysis script): no SCHED_FIFO, no CPU pinning, no memory locking.
/// A program driving a real device keeps servo::ServoThreadConfig's defaults (all three on).
inline session::LiveSessionConfig polite_config(double rate_hz, const servo::WorkspaceTransform& world_T_device) {
  session::LiveSessionConfig c;
  c.servo.rate_hz = rate_hz;
  c.servo.sched_fifo = false;
  c.servo.pin_cpu = false;
  c.servo.lock_memory = false;
  c.servo.world_T_device = world_T_device;
  return c;
}

/// Polls live.observe() every 0.5 ms until `done(observed)` is true or `timeout_s` [s] of
/// wall time passed. @return whether `done` became true. Any thread but the servo's.
template <class Done>
bool wait_until(const session::LiveSession& live, Done done, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!done(live.observe())) {
    if (std::chrono::steady_clock::now() >= end) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  return true;
}

/// A carve edit for LiveSession::submit() / EditSession::apply(): removes material in a ball
/// of `radius_m` [m] around `centre_m` (grid-world [m], e.g. the VHIP of observe()), moving
/// each voxel toward `targets.empty` by at most `strength` [value units] at the centre
/// (session/brush.h: the weights). `targets`: session::default_targets(volume, iso).
inline session::EditEvent carve_at(const core::Vec3& centre_m, double radius_m, double strength,
                                   const session::BrushTargets& targets) {
  session::EditEvent e;
  e.kind = session::EditEvent::Kind::kBrush;
  e.brush.kind = session::BrushKind::kCarve;
  e.brush.centre_m = centre_m;
  e.brush.radius_m = radius_m;
  e.brush.strength = strength;
  e.brush.targets = targets;
  return e;
}

}  // namespace isotouch
