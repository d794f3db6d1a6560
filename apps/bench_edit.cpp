// bench_edit.cpp - STUB (lead) until the bench-edit helper fills it in.
#include "bench_edit.h"

#include <iostream>

namespace isotouch::app {

Subcommand add_bench_edit_command(CLI::App& bench) {
  auto* sub = bench.add_subcommand("edit", "Edit-to-haptics latency and edit rate while sculpting the chest CT");
  return {sub, [](const std::string&) {
            std::cerr << "isotouch bench edit: not implemented yet\n";
            return 2;
          }};
}

}  // namespace isotouch::app
