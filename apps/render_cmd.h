// render_cmd.h - `isotouch render` and `isotouch bench render`. The pictures themselves
// (PNG writing, cameras, overlays, the run report's picture) are the run job's: run/picture.h.
#pragma once
#include "picture.h"
#include "subcommand.h"
#include "trace_csv.h"

namespace isotouch::app {

/// Adds `render` to the top-level command line.
Subcommand add_render_command(CLI::App& cli);
/// Adds `render` under `bench`.
Subcommand add_bench_render_command(CLI::App& bench);

// The picture names the commands (and the sculpting app) use without a prefix.
using run::default_camera;
using run::load_scene_volume;
using run::PictureRequest;
using run::probe_prims;
using run::probe_size_m;
using run::read_trace_csv;
using run::render_picture;
using run::render_run_picture;
using run::RunPicture;
using run::scene_raycast_field;
using run::write_png;

}  // namespace isotouch::app
