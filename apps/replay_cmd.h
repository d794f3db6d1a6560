// replay_cmd.h - `isotouch replay FILE`: plays a recording back (apps/record.h) and checks
// the forces (issue 9, item 5). OWNER: record-replay helper.
#pragma once
#include "subcommand.h"

namespace isotouch::app {

/// Adds `replay` to the top-level command line.
Subcommand add_replay_command(CLI::App& cli);

}  // namespace isotouch::app
