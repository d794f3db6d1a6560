// stability_cmd.h - `isotouch stability`: measured K_max against the passivity bound.
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `stability` to the top-level command line (the experiments: bench/stability_report.h).
Subcommand add_stability_command(CLI::App& cli);

}  // namespace isotouch::app
