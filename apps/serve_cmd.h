// serve_cmd.h - `isotouch serve SCENE`: the OpenIGTLink server (service/serve.h).
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `serve` to the top-level command line. Exit 0 after --seconds; 1 bad input (the
/// scene, a port that cannot be opened); 2 usage; 4 servo faults; 128 + N on signal N.
Subcommand add_serve_command(CLI::App& cli);

}  // namespace isotouch::app
