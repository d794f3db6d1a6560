// trace_figures.h - the figures of a run's ticks: tick times, contact forces and their
// steps, the stroke and lift-off, and the VHIP's true distance from the isosurface.
#pragma once
#include <utility>
#include <vector>

#include "edit_driver.h"
#include "headless.h"
#include "run_metrics.h"
#include "scene_setup.h"

namespace isotouch::run {

// The trace's figures into `m`: tick times, contact forces and their steps, the stroke and
// lift-off, and the VHIP's surface error (against the edited volume a tick read, with edits).
// Returns how many contact ticks found a surface (true distance; unfiltered data).
std::pair<long, long> trace_figures(const std::vector<sim::TraceRow>& trace, const SceneSetup& setup,
                                    const EditDriver* edits, RunMetrics& m);

}  // namespace isotouch::run
