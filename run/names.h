// names.h - the names run/ takes from other folders without a prefix (one place, as
// servo/core_names.h does for servo/).
#pragma once
#include "isotouch/session/edit_session.h"
#include "isotouch/io/files.h"
#include "isotouch/io/output_file.h"
#include "isotouch/io/record.h"
#include "isotouch/io/run_folder.h"
#include "isotouch/io/scene.h"
#include "isotouch/eval/stats.h"
#include "isotouch/session/stop_signal.h"
#include "isotouch/eval/surface_distance.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_write.h"

namespace isotouch::run {
using core::cross;
using core::dot;
using core::to_string;
using eval::distance_to_isosurface;
using eval::first_order_distance;
using eval::median;
using eval::percentile;
using io::draw_with_gnuplot;
using io::extract_mesh;
using io::gnuplot_quote;
using io::load_any_volume;
using io::save_recording;
using io::save_vdb;
using io::temp_name;
using io::volume_crc32;
using io::write_file_atomic;
using io::write_stl_binary;
using session::throw_if_stop_requested;
using session::to_string;
using core::Vec3;
using eval::SurfaceDistance;
using io::BrushSpec;
using io::EditsSpec;
using io::PassSpec;
using io::Recording;
using io::RunFolder;
using io::SaveVdbOptions;
using io::Scene;
using io::SceneError;
using io::TimedEdit;
using session::EditEvent;
using session::EditOutcome;
using session::EditSession;
using session::Interrupted;
}  // namespace isotouch::run
