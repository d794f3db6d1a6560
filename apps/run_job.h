// run_job.h - the run job's names that the commands (run, replay, run --live, bench edit,
// the sculpting app) use without a prefix. The job itself is a library: run/.
#pragma once
#include "isotouch/run/live_run.h"
#include "isotouch/run/run_metrics.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"

namespace isotouch::app {

using run::brush_at_tool;
using run::drill_rate;
using run::edit_tick;
using run::LiveOptions;
using run::run_live;
using run::write_hand_path;
using run::EditFigures;
using run::make_brush;
using run::PassFigure;
using run::recording_header;
using run::run_scene;
using run::RunMetrics;
using run::RunOptions;
using run::scene_passes;
using run::scene_sample_format;
using run::SceneSetup;
using run::setup_scene;

}  // namespace isotouch::app
