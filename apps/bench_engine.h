// bench_engine.h - `isotouch bench engine` (issue 8, item 7).
#pragma once
#include "subcommand.h"

namespace isotouch::app {
/// Adds `engine` under `bench`.
Subcommand add_bench_engine_command(CLI::App& bench);
}  // namespace isotouch::app
