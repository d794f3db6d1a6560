// run_scene.h - `isotouch run`'s job: one scene end to end (set-up, the live session in
// simulated mode, figures, pictures, summary.json and report.md).
#pragma once
#include <iosfwd>
#include <string>

#include "isotouch/run/run_metrics.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/scene_setup.h"

namespace isotouch::run {

/// Run one scene end to end and write its outputs into options.out_dir.
/// @throws engine::VolumeError, SceneError, std::runtime_error with a clear reason.
RunMetrics run_scene(const io::Scene& scene, const RunOptions& options, std::ostream& log);

/// While alive, a second SIGINT / SIGTERM (which ends the process at once) leaves `dir`'s
/// summary.json saying "interrupted" rather than "running" (session::set_last_words).
/// For a command that keeps a run folder (io::RunFolder) while it works.
class LastWordsWhileRunning {
 public:
  LastWordsWhileRunning(const io::Scene& scene, const std::string& dir);
  ~LastWordsWhileRunning();
  LastWordsWhileRunning(const LastWordsWhileRunning&) = delete;
  LastWordsWhileRunning& operator=(const LastWordsWhileRunning&) = delete;
};

}  // namespace isotouch::run
