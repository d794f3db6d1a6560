// live_run.h - what `isotouch run SCENE --live` runs: the scene in real time on the live session's
// threads (session/live_session.h): the servo thread drives the simulated device (the
// scene's scripted hand) at the scene's rate, the edit thread applies the button drill and
// the timeline, and `--record FILE` streams a format 3 recording that `isotouch replay`
// reproduces bit for bit.
#pragma once
#include <iosfwd>
#include <string>

#include "isotouch/run/names.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"

namespace isotouch::run {

struct LiveOptions {
  RunOptions run;                ///< device, progress, record_path; out_dir: "" or where trace.csv, report.md, summary.json go
  bool sched_fifo = true;        ///< ask for SCHED_FIFO and pinning (refused: said, not fatal)
  double flush_interval_s = 0.1; ///< the recording's chunk interval [s]
  std::string haptic = "sim";    ///< the device: `--haptic KIND:ARGS` (run/haptic_device.h)
};

/// Runs `scene` live for its script's duration (or until SIGINT / SIGTERM). Prints the
/// servo's ticks, missed deadlines and faults, the edits and their edit-to-haptics latency.
/// With a hid or emu device (or any device whose reports the servo zeroed), also prints the
/// device's counters (reports, refused, gaps, stale / disconnected / fault ticks, ramps,
/// clamps) and the force it rendered. With options.run.out_dir, writes trace.csv (the
/// renderer's ticks), report.md and summary.json there (the folder locked and marked as
/// `isotouch run` does; "interrupted" after a signal).
/// @return 0; 4 when servo ticks were faults; 5 when the device was disconnected, faulty or
/// sent refused reports during the run; 128 + the signal when SIGINT / SIGTERM stopped
/// it (the servo stopped with zero force, the recording closed and complete). @throws as run_scene, io::RecordingError.
int run_live(const io::Scene& scene, const LiveOptions& options, std::ostream& log);

/// Writes the scene's scripted hand target as isotouch-devemu's --path CSV (t_s,x_m,y_m,z_m,
/// device frame, every ms), so the emulator's hand plays the scene. @return 0.
/// @throws as setup_scene; std::runtime_error if FILE cannot be written.
int write_hand_path(const io::Scene& scene, const std::string& path, std::ostream& log);

}  // namespace isotouch::run
