// render_cmd.h - `isotouch render`: a scene's isosurface to a PNG (run/render_job.h).
#pragma once
#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Adds `render` to the top-level command line.
Subcommand add_render_command(CLI::App& cli);

}  // namespace isotouch::app
