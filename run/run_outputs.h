// run_outputs.h - a run's plots and pictures, and the files, figures and pictures of its
// edits.
#pragma once
#include <iosfwd>
#include <string>
#include <vector>

#include "isotouch/run/edit_driver.h"
#include "isotouch/sim/headless.h"
#include "isotouch/run/run_metrics.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/sim/script.h"

namespace isotouch::run {

/// force_depth.png and tick_time.png from DIR/trace.csv with gnuplot (plots.gp beside them).
/// @return true when drawn; `note` says why not.
bool draw_plots(const io::Scene& scene, const std::string& dir, const sim::TouchScript& script, std::string& note);

// The path for a picture, thinned to about 600 ticks (each is an overlay every pixel
// tests: a 6000-tick path takes minutes on lavapipe); the tick of the largest force kept.
std::vector<sim::TraceRow> thin_path(const std::vector<sim::TraceRow>& trace);

// The figures, files and pictures of a run with edits, into m.edits; drilled.stl's
// coordinates in `mesh_units` (physical frame, LPS).
void finish_edits(const io::Scene& scene, SceneSetup& setup, const EditDriver& d, const std::vector<sim::TraceRow>& trace,
                  const std::string& dir, io::MeshUnits mesh_units, RunMetrics& m, std::ostream& log);

}  // namespace isotouch::run
