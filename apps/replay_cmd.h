// replay_cmd.h - `isotouch replay FILE`: a recording played back and checked (run/replay.h).
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `replay` to the top-level command line. Exit 0: every force identical; 1: forces
/// differ (the first differing tick printed); 2: bad input (unreadable recording, changed
/// scene, ...); 3: the pipeline could not run (e.g. no Vulkan device).
Subcommand add_replay_command(CLI::App& cli);

}  // namespace isotouch::app
