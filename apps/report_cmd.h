// report_cmd.h - `isotouch report`: error against run time, every algorithm and option.
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `report` to the top-level command line (the sweep: bench/error_report.h).
Subcommand add_report_command(CLI::App& cli);

}  // namespace isotouch::app
