// run_report.h - a run's summary.json and report.md, from its figures.
#pragma once
#include <array>
#include <optional>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "isotouch/run/run_metrics.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/engine/volume.h"
#include "isotouch/servo/live_passivity.h"

namespace isotouch::run {

// "finite values [lo, hi]" plus the NaN/Inf counts; never a range for no finite voxels.
std::string value_range_text(const engine::Volume& vol, const RunMetrics& m);
/// The direction matrix as "[[a, b, c], [d, e, f], [g, h, i]]" (4 digits).
std::string direction_text(const std::array<double, 9>& d);

// The run's summary.json ("status": "complete": written last, once every other output is whole).
nlohmann::ordered_json summary_json(const io::Scene& scene, const SceneSetup& setup, const RunMetrics& m, long found,
                                    long raw_found, bool with_edits);

/// summary.json's "passivity": the live servo's passivity observer and controller (energies
/// in J, device frame; active_ticks: ticks the controller added damping; restarts: the
/// observer started afresh on a reconnection or a device clock reset or jump). "status":
/// "run", or "not run" (no servo thread: no figures, rather than zeros that look measured).
nlohmann::ordered_json passivity_json(const std::optional<servo::PassivityStats>& p);

// The run's report.md.
std::string report_markdown(const io::Scene& scene, const SceneSetup& setup, const RunMetrics& m, long found,
                            long raw_found, bool with_edits);

}  // namespace isotouch::run
