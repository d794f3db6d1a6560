// run_scene.h - `isotouch run`'s job: one scene end to end (set-up, the live session in
// simulated mode, figures, pictures, summary.json and report.md).
#pragma once
#include <iosfwd>

#include "run_metrics.h"
#include "scene.h"
#include "scene_setup.h"

namespace isotouch::run {

/// Run one scene end to end and write its outputs into options.out_dir.
/// @throws engine::VolumeError, SceneError, std::runtime_error with a clear reason.
RunMetrics run_scene(const io::Scene& scene, const RunOptions& options, std::ostream& log);

}  // namespace isotouch::run
