// export_cmd.h - `isotouch export`: a volume or a scene's volume to OpenVDB .vdb and its
// isosurface to STL / OBJ / PLY (issue 9, item 4).
#pragma once
#include "subcommand.h"

namespace isotouch::app {
/// Adds `export` to the top-level command line.
Subcommand add_export_command(CLI::App& cli);
}  // namespace isotouch::app
