// app.h - isotouch-sculpt: a window where a person sculpts a volume and feels it.
//
// One LiveSession (servo thread at the scene's rate on a simulated device coupled to the
// mouse, edit thread, optional recorder) holds the volume; the window's thread draws each
// frame with the compute ray caster (engine::RayCaster, updated brick by brick after each
// applied edit), steers the hand target from the mouse and submits the tools' brushes,
// undo and redo through LiveSession::submit.
#pragma once
#include <memory>
#include <optional>
#include <ostream>
#include <string>

#include "isotouch/io/mesh_units.h"

namespace isotouch::sculpt {

/// What a session restarted at a new isovalue keeps: the edited volume, the camera, the
/// tool (defined in sculpt_app.h).
struct Carried;

struct Options {
  std::string input;                ///< a scene (.json) or a volume file
  std::optional<double> iso;        ///< a volume's isovalue (none: engine::choose_isovalue's); a scene's, overriding its own
  std::string inside = "above";     ///< a volume's inside: "above" or "below"
  std::string script;               ///< input script (JSON), "" = none
  std::string screenshot;           ///< PNG of the last frame; script screenshots go to its folder
  /// PNG of what the X server shows in the window at exit (after the last present: the
  /// picture with the panels and slices as the user sees them), read back from the server.
  std::string window_shot;
  /// How frames reach the screen: "auto" (X shared memory on a CPU device with a local X
  /// server, else the swapchain), "shm" or "swapchain" (sculpt/window.h).
  std::string present = "auto";
  std::string record;               ///< the session's recording (scenes only)
  /// The edit journal (io/journal.h): every applied edit appended to
  /// $XDG_STATE_HOME/isotouch/sculpt-CRC.journal, so a crash loses none (false: --no-journal).
  bool journal = true;
  /// A journal a session that did not end cleanly left: "yes" restore it, "no" drop it (kept
  /// aside), "ask" on the terminal (without one: not restored, kept aside).
  std::string restore = "ask";
  std::string save_path;            ///< Ctrl+S target (.vdb, .nrrd, .mha, .nii, .nii.gz); default INPUT-sculpted.vdb
  std::string export_path;          ///< Ctrl+E target (.stl, .obj or .ply); default INPUT-sculpted.stl
  io::MeshUnits mesh_units = io::MeshUnits::kMillimetre;  ///< Ctrl+E's coordinates (physical frame, LPS)
  int frames = 0;                   ///< exit 0 after this many frames (0: until closed)
  int width = 1024, height = 768;
  double render_scale = 1.0;        ///< the ray caster draws at this fraction of the window's pixels (upscaled)
  /// While the view moves (camera or window), frames drawn whole keep within this budget [ms]:
  /// the ray caster's scale (at most render_scale) chosen per frame from the last frames'
  /// cost (engine/frame_budget.h), upscaled bilinearly; a still view is drawn at render_scale.
  /// 0: always render_scale; so are --bench's rounds (they measure the renderer; its
  /// moving-frames phase uses the budget), script screenshots and --sim-clock runs.
  double frame_budget_ms = 33;
  double edit_wait_ms = 50;         ///< a frame waits this long at most for the brush it submitted (0: never)
  bool bench = false;               ///< run the built-in sculpt (unless --script) and print verdicts against the targets
  /// With the built-in bench: its rounds repeat until the servo has ticked this many times,
  /// then the servo runs alone for as many ticks (0: no servo-alone phase, no servo verdict).
  long bench_ticks = 20000;
  /// Feel every tool as the point (the probe of old, for comparison); by default a carve or
  /// drill brush is felt as the spherical tool of its radius, the brush cutting to its surface.
  bool point_probe = false;
  bool stats = false;               ///< print frame time, edit-to-pixels and servo figures at exit
  bool validation = false;          ///< Vulkan validation layer; any message makes the exit code 3
  /// The session's simulated mode on the frame's clock: each frame advances the servo by
  /// sim_frame_ms of simulated time (whole ticks) on this thread, and the edits are applied
  /// in step with it, so a script gives the same recording and screenshots every run. The
  /// window's own mouse and keys are ignored (the script is the only input); the mouse probe only.
  bool sim_clock = false;
  double sim_frame_ms = 1000.0 / 30.0;
  bool sched_fifo = true;           ///< ask for SCHED_FIFO, pinning and locked memory for the servo thread (refused: a note)
  /// Keep the display server (the local X server) off the servo thread's CPU while the
  /// window is open, and present from another CPU (servo/cpu_placement.h says why).
  bool display_off_servo_cpu = true;
  bool overlay = true;              ///< the Dear ImGui tool and stats panels (a build with Dear ImGui)
  /// The slice views (axial, coronal, sagittal through the HIP) at the window's right edge,
  /// in the screenshots too; H hides them with the overlay.
  bool slices = true;
  /// Writes the slices (one pixel per voxel) and slices.json here at exit, and into
  /// DIR/NAME/ with each script screenshot NAME.png ("" = never).
  std::string slices_png;
  /// The ray caster's tile starts (engine::RaycastStyle::tile_starts; off only to measure
  /// what they save: the picture is the same).
  bool tile_starts = true;
  std::string device;               ///< Vulkan device choice
  /// The haptic device: "mouse" (a simulated device coupled to the hand the mouse steers) or
  /// a `--haptic` spec of `isotouch run --live` other than sim (null, playback:FILE, hid:..., emu:SOCKET,
  /// openhaptics[:NAME], forcedimension[:INDEX], igtl:HOST:PORT[:STREAM]).
  std::string haptic = "mouse";
  /// Run a stiffness above the stability bound (an igtl: device's, at its measured rate), as
  /// the scene's servo.allow_unstable_stiffness.
  bool allow_unstable_stiffness = false;
  /// Set by the isovalue slider's restart: the volume as edited (not re-read from `input`),
  /// the camera and the tool.
  std::shared_ptr<const Carried> carried;
};

/// The servo verdict of --bench counts misses over at least this many ticks, sculpting and alone.
constexpr long kBenchMinTicks = 20000;

/// The servo verdict of --bench: the misses while sculpting are at most the servo alone's,
/// scaled to the sculpting ticks (ref), + 3 sqrt(ref) (three standard deviations of a Poisson
/// count). `allowed` gets ref + 3 sqrt(ref).
bool servo_misses_pass(long sculpt_missed, long sculpt_ticks, long alone_missed, long alone_ticks, double& allowed);

/// Runs the window until it is closed, the script quits or `frames` frames were drawn.
/// Returns the exit code: 0, 1 on bad input or set-up failure (reason on `log`), 3 if
/// validation reported messages.
/// A volume file or scene dropped on the window (or a script's "drop") that could be read
/// sets `*reopen` to the options for it (a volume: the isovalue its file chooses) and ends
/// this session; the caller runs it next. One that cannot be read shows its error (log and
/// window title) and the session goes on with the old volume. The isovalue slider (or a
/// script's "iso") ends the session the same way, with the edited volume carried over (the
/// undo history starts afresh, a recording stops).
int run_sculpt(const Options& o, std::ostream& log, std::optional<Options>* reopen = nullptr);

/// Dropped files still loading on their (detached) threads, abandoned by the sessions that
/// started them. The process must not run its static destructors under such a thread: exit
/// with std::_Exit after flushing when this is not 0.
int loads_running();

}  // namespace isotouch::sculpt
