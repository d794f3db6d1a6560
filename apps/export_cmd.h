// export_cmd.h - `isotouch export`: a volume to .vdb and its isosurface to STL / OBJ / PLY.
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `export` to the top-level command line (the export: run/export.h).
Subcommand add_export_command(CLI::App& cli);

}  // namespace isotouch::app
