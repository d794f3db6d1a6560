// check_cmd.h - `isotouch check`: the engine's passes against their CPU references.
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `check` to the top-level command line.
Subcommand add_check_command(CLI::App& cli);

}  // namespace isotouch::app
