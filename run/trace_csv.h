// trace_csv.h - trace.csv, one row per tick in the volume's physical frame: written by
// `isotouch run`, read back by `isotouch render --trace`.
#pragma once
#include <string>
#include <vector>

#include "isotouch/sim/headless.h"
#include "isotouch/engine/volume.h"

namespace isotouch::run {

// One row per tick; points and forces in the volume's physical frame
// (world = origin + D (spacing * index)), not the grid frame the servo works in.
std::string trace_csv(const std::vector<sim::TraceRow>& trace, const engine::Volume& vol);

/// trace.csv (physical frame, written by `isotouch run`) read back into grid-world rows
/// (t, HIP, VHIP, force, contact). @throws std::runtime_error naming the file, line and column.
std::vector<sim::TraceRow> read_trace_csv(const std::string& path, const engine::Volume& vol);

}  // namespace isotouch::run
