// run_cmd.h - `isotouch run`: a scene simulated end to end (the run job, run/run_scene.h),
// or in real time with --live (live_cmd.h).
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `run` to the top-level command line.
Subcommand add_run_command(CLI::App& cli);

}  // namespace isotouch::app
