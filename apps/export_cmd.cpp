#include "export_cmd.h"

#include <iostream>

namespace isotouch::app {
Subcommand add_export_command(CLI::App& cli) {
  Subcommand s;
  s.app = cli.add_subcommand("export", "Write a volume as .vdb and its isosurface as STL/OBJ/PLY (not built yet)");
  s.run = [](const std::string&) {
    std::cerr << "isotouch export: not built yet\n";
    return 2;
  };
  return s;
}
}  // namespace isotouch::app
