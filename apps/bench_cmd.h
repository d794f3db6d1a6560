// bench_cmd.h - `isotouch bench`: servo-rt, table1, engine, render, edit, device.
#pragma once
#include <vector>

#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `bench` and its subcommands to the top-level command line; main() runs the one parsed.
std::vector<Subcommand> add_bench_commands(CLI::App& cli);

}  // namespace isotouch::app
