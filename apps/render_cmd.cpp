#include "render_cmd.h"

#include <iostream>

namespace isotouch::app {
Subcommand add_render_command(CLI::App& cli) {
  Subcommand s;
  s.app = cli.add_subcommand("render", "Ray-cast the scene's isosurface to a PNG (not built yet)");
  s.run = [](const std::string&) {
    std::cerr << "isotouch render: not built yet\n";
    return 2;
  };
  return s;
}
Subcommand add_bench_render_command(CLI::App& bench) {
  Subcommand s;
  s.app = bench.add_subcommand("render", "ms per frame of the ray caster (not built yet)");
  s.run = [](const std::string&) {
    std::cerr << "isotouch bench render: not built yet\n";
    return 2;
  };
  return s;
}
}  // namespace isotouch::app
