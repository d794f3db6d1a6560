// render_cmd.h - `isotouch render` and `isotouch bench render` (issue 10).
#pragma once
#include "subcommand.h"

namespace isotouch::app {
/// Adds `render` to the top-level command line.
Subcommand add_render_command(CLI::App& cli);
/// Adds `render` under `bench`.
Subcommand add_bench_render_command(CLI::App& bench);
}  // namespace isotouch::app
