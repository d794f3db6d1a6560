// sweep_cmd.h - `isotouch sweep`: the Dask sweep (python/isotouch/sweep.py) under the main command.
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `sweep`: every argument after it goes to `python3 -m isotouch.sweep` (docs/sweeps.md),
/// run with the isotouch Python module of this build or installation on PYTHONPATH.
Subcommand add_sweep_command(CLI::App& cli);

}  // namespace isotouch::app
