// bench_edit.h - `isotouch bench edit`: edit-to-haptics latency, sustained edit rate and
// servo misses while sculpting the chest CT, against a dense full recompute (issue 9,
// item 7). OWNER: bench-edit helper.
#pragma once
#include "subcommand.h"

namespace isotouch::app {

/// Adds `edit` under `isotouch bench`.
Subcommand add_bench_edit_command(CLI::App& bench);

}  // namespace isotouch::app
