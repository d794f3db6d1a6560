#include "bench_engine.h"

#include <iostream>

namespace isotouch::app {
Subcommand add_bench_engine_command(CLI::App& bench) {
  Subcommand s;
  s.app = bench.add_subcommand("engine", "Engine passes dense and sparse, GPU and CPU (not built yet)");
  s.run = [](const std::string&) {
    std::cerr << "isotouch bench engine: not built yet\n";
    return 2;
  };
  return s;
}
}  // namespace isotouch::app
