// run_metrics.h - the figures of one `isotouch run`: engine, servo, contact, surface
// error and edits (what summary.json and report.md say).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "isotouch/engine/pass_desc.h"
#include "isotouch/core/vec3.h"

namespace isotouch::run {

/// One pass (dense) or stage (sparse) as it ran.
struct PassFigure {
  std::string label;   ///< engine::PassTiming::label
  double ms = -1;      ///< GPU: device time (timestamps; -1 if none); CPU: wall time [ms]
  int dispatches = 0;  ///< GPU dispatches; 0 on the CPU
};

/// What the scene's edits did (filled by run_scene when the scene has an "edits" section).
struct EditFigures {
  bool present = false;            ///< the scene has edits
  /// The scene brush's drill rate in value units per (N s), and as the fraction of the
  /// brush's |material - empty| range per (N s) (the same on every volume).
  double drill_rate_value_per_n_s = 0, drill_removal_per_n_s = 0;
  long events = 0;                 ///< EditEvents applied (brushes, strokes, undo, redo)
  long brushes = 0;                ///< brush applications
  long timeline_brushes = 0, button_brushes = 0;  ///< of which from the timeline / the button
  long undos = 0, redos = 0;
  /// Edits that did nothing, and why: undo / redo with nothing to undo or redo, brushes that
  /// changed no voxel (of which entirely outside the volume, and "vhip" brushes before any
  /// contact), timeline entries after the script's end (never applied). `notes` says each
  /// kind once with its first time, for the console, summary.json and the report.
  long undo_nothing = 0, redo_nothing = 0, brushes_changing_nothing = 0, brushes_outside = 0,
       vhip_before_contact = 0, timeline_after_end = 0;
  std::vector<std::string> notes;
  long publications = 0;           ///< snapshots published (samples changed)
  std::uint64_t last_version = 1;  ///< SampleField::version of the last snapshot
  long dirty_bricks = 0;           ///< sum over applications of the bricks whose voxels changed
  long recomputed_bricks = 0;      ///< sum over updates of LiveUpdateStats::recomputed
  long gpu_updates = 0;            ///< updates whose filters ran on the GPU (LiveUpdateStats::gpu)
  double update_ms_median = 0, update_ms_max = 0;  ///< session::EditSession::apply wall time, publishing events [ms]
  double brush_ms_median = 0;      ///< BrushResult::wall_ms median [ms]
  bool brushes_on_gpu = false;     ///< Sculptor::on_gpu(): a Vulkan device was given to the brushes
  long brushes_on_device = 0;      ///< brush applications that ran on the Vulkan device (BrushResult::on_device)
  long brushes_on_cpu = 0;         ///< ... on the CPU reference (no device, or few bricks: Sculptor::cpu_max_bricks)
  std::uint64_t history_bytes = 0, history_limit_bytes = 0;  ///< undo history at the end
  std::size_t history_dropped = 0; ///< strokes dropped to stay under the limit
  double first_edit_t_s = -1;      ///< time of the first brush application [s] (-1: none)
  /// Contact ticks that read an edited snapshot (version > 1): their surface error is
  /// measured against the edited volume they read (dense samples rebuilt per snapshot).
  long contact_ticks_after_edit = 0;
  /// Inside voxels before minus after, times the voxel volume [mm^3] (the scene's isovalue
  /// and inside, NaN counts as outside): what the edits removed (negative: added; the
  /// report and summary.json say "added" then, summary.json's removed_mm3 / added_mm3 >= 0).
  double removed_mm3 = 0;
  long inside_voxels_before = 0, inside_voxels_after = 0;
  /// Depth along the press direction (-contact normal) below the initial contact point [m]:
  /// deepest HIP and VHIP of the run.
  double max_hip_depth_m = 0, max_vhip_depth_m = 0;
  /// Drill scenes: the breakthrough (|F| falling to a tenth of the drill threshold and staying
  /// there while the button is down, eval::find_breakthrough) and the open radius of the
  /// channel along the burr centres' path (eval::measure_channel, burr radius = the tool's,
  /// else the brush's).
  bool drill = false;
  bool breakthrough = false;
  double breakthrough_t_s = 0, breakthrough_from_n = 0, breakthrough_to_n = 0, breakthrough_fall_s = 0;
  bool channel_measured = false;
  int channel_slices = 0;
  /// The brush that cut at the VHIP: its radius and how far it reaches past the burr's
  /// surface [m] (run::tool_brush_margin_m; 0 with a point tool).
  double cut_radius_m = 0, cut_margin_m = 0;
  double burr_radius_m = 0, channel_min_open_radius_m = 0, channel_min_at_depth_m = 0, channel_min_fraction = 0;
  /// channel_section.png (run/channel_section.h: the narrowest slice across and the channel
  /// along, from the voxels after drilling): drawn, or why not.
  bool channel_section_drawn = false;
  std::string channel_section_note;
  std::string vdb_file, nrrd_file, stl_file;  ///< drilled.vdb / .nrrd / .stl as written ("" if not)
  /// drilled.seg.nrrd as written ("" if not): a labelled scene's label map after the edits
  /// (removed voxels 0), beside the saved volume, for 3D Slicer (materials/label_export.h).
  std::string seg_file;
  std::string stl_units;           ///< drilled.stl's coordinates: "mm" or "m" (physical frame, LPS)
  std::string files_note;          ///< why a file was not written
  /// drilled.stl's mesh (io::extract_mesh: coincident vertices welded, zero-area triangles
  /// dropped; io::mesh_stats): closed when every edge is in exactly two triangles; its
  /// enclosed volume (divergence theorem, > 0 with normals out) beside the inside voxels'
  /// volume after the edits [mm^3].
  bool mesh_measured = false;
  std::size_t mesh_triangles = 0, mesh_dropped_triangles = 0, mesh_boundary_edges = 0, mesh_nonmanifold_edges = 0;
  bool mesh_closed = false;
  double mesh_volume_mm3 = 0, inside_voxels_volume_mm3 = 0;
  bool before_after_drawn = false; ///< before.png and after.png written
  /// section_before.png / section_after.png: cut open through the press axis (a clip plane
  /// containing it, seen from the side), where a hole through a thin wall shows.
  bool sections_drawn = false;
  std::string sections_note;       ///< why they were not drawn
  /// drill.png: before | after side by side, a ring marker at the site, a zoomed inset.
  bool site_figure_drawn = false;
  std::string site_figure_note;    ///< why it was not drawn
  bool plot_drawn = false;         ///< edits.png written
  /// Labelled scenes with a critical material: the margin warning (materials::CriticalMargin)
  /// fed every tick with the cutting brush's surface distance to the nearest critical voxel
  /// (materials::CriticalDistance::lower_bound of its centre minus its radius): a timeline
  /// drill or carve of that tick (or of its open stroke) with its own centre and radius, else
  /// the button drill's burr at the VHIP. One per critical material, each at its own margin
  /// against the distance to its own voxels.
  struct CriticalFigures {
    std::string name;
    double margin_m = 0;             ///< the warning distance: its margin_mm [m]
    long entries = 0;                ///< times the burr's surface entered the margin
    double time_inside_s = 0;        ///< time inside the margin [s]
    double closest_approach_m = std::numeric_limits<double>::infinity();  ///< smallest surface distance [m] (< 0: the brush overlapped the structure's voxel centres; inf: never measured)
    double first_entry_t_s = -1;     ///< [s], -1: never entered
    long voxels_changed = 0;         ///< its voxels whose value differs after the run (0: never removed)
  };
  std::vector<CriticalFigures> critical;
  std::string before_after_note;   ///< caption, or why pictures / plot were not drawn
};

/// Figures of one run (also written to summary.json).
struct RunMetrics {
  std::string volume_path;
  std::array<int, 3> dims{};
  core::Vec3 spacing_m;
  std::string gpu_device;
  std::string gpu_device_type;
  /// The engine ran on the CPU backend (no Vulkan context): the gpu_* figures are its own.
  bool cpu_backend = false;
  double gpu_gradient_ms = 0, gpu_upload_ms = 0, gpu_download_ms = 0, gpu_submit_wall_ms = 0;
  int gpu_slabs = 0;
  bool gpu_timestamps = false;
  double cpu_gradient_ms = 0;
  double max_abs_diff = 0, max_rel_diff = 0, max_abs_diff_xyz[3] = {0, 0, 0};
  long ticks = 0;
  double tick_ns_median = 0, tick_ns_p99 = 0, tick_ns_max = 0, tick_ns_mean = 0;
  long contact_ticks = 0, plane_updates = 0, saturated_ticks = 0, fault_ticks = 0;
  double max_force_n = 0, max_penetration_m = 0, mean_contact_force_n = 0;
  /// Largest change of |F| [N] between two consecutive ticks that are both in contact.
  double max_force_step_n = 0;
  double max_force_step_t_s = 0;  ///< time of the second tick of that step [s]
  /// Largest change of the force vector |F_k - F_k-1| [N] between two consecutive ticks
  /// that are both in contact: a turn of the force that |F| alone cannot see.
  double max_force_vector_step_n = 0;
  double max_force_vector_step_t_s = 0;  ///< time of the second tick of that step [s]
  /// Colgate-Schenkel bound 2 (b - |B|) / T [N/m] for the scene (b = device + hand
  /// damping, B the servo's damping, T = 1 / rate), and whether K exceeds it.
  double k_bound_n_per_m = 0;
  bool k_above_bound = false;
  /// Largest |F| [N] on a contact tick whose next tick has no contact (every release, the
  /// HIP inside the object or not): the force drop that max_force_step_n cannot see.
  double max_release_step_n = 0;
  double max_release_step_t_s = 0;  ///< time of the tick with no contact [s]
  /// Largest change of |F| [N] between any two consecutive ticks, in contact or not.
  double max_any_step_n = 0;
  double max_any_step_t_s = 0;  ///< time of the second tick of that step [s]
  /// True distance [m] of the VHIP from the trilinear isosurface over the contact ticks
  /// (eval/surface_distance.h: bounded search, accurate to 1e-3 voxel), RMS and max over
  /// the ticks where a surface was found within surface_search_radius_m.
  /// Both 0 (and null in summary.json) when no contact tick found a surface.
  double surface_err_rms_m = 0, surface_err_max_m = 0;
  long surface_err_not_found_ticks = 0;  ///< contact ticks with no surface within the radius
  double surface_search_radius_m = 0;
  /// The old first-order estimate |f - tau| / |grad f|, kept beside the true distance to
  /// show the difference, over the contact ticks where it is a distance at all: finite and
  /// at most first_order_bound_m, the volume's diagonal (where |grad f| is near 0 it grows
  /// without bound). The ticks left out are counted; both figures 0 when none is kept.
  double first_order_err_rms_m = 0, first_order_err_max_m = 0;
  long first_order_kept_ticks = 0, first_order_left_out_ticks = 0;
  double first_order_bound_m = 0;  ///< the volume's diagonal [m]
  std::string orientation;               ///< e.g. "LPS" (engine::Volume::orientation)
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major D
  std::size_t nan_voxels = 0, inf_voxels = 0;
  bool plots_drawn = false;
  std::string plot_note;
  /// surface.png: the isosurface, the HIP path and the contact points coloured
  /// by |F| (run::render_run_picture); caption, or why it was not drawn.
  bool picture_drawn = false;
  std::string picture_note;
  /// overview.png: the whole object upright with the HIP's path (run::render_overview);
  /// report.md's sentence on it (run::overview_sentence), or why it was not drawn.
  bool overview_drawn = false;
  std::string overview_note;

  // Engine: what computed the published samples.
  std::string engine_mode;     ///< "dense" or "sparse" (the scene's engine.mode)
  std::string engine_ran;      ///< what actually computed the published snapshot (GPU)
  std::string engine_fallback; ///< why the sparse GPU chain was not used; empty if it was (or mode is dense)
  std::string reference_ran;   ///< what computed the CPU reference
  std::string sample_format;   ///< "fp32", "fp16", "unorm16"
  std::vector<engine::PassDesc> passes;  ///< the scene's list, as run
  std::vector<PassFigure> gpu_passes, cpu_passes;
  std::string engine_describe; ///< PassChain/SparseChain::describe(): pipelines, buffers created and left out
  std::size_t bricks_total = 0, bricks_candidates = 0, bricks_active = 0;  ///< sparse only
  std::uint64_t snapshot_bytes = 0;    ///< bytes of the published snapshot
  std::uint64_t dense_fp32_bytes = 0;  ///< voxels * 16: the dense fp32 snapshot
  double publish_ms = 0;               ///< host time building the published snapshot (sparse) [ms]
  /// Angle [deg] between the force directions of two consecutive contact ticks, RMS and max:
  /// how rough the rendered surface feels (noise in the data shows here).
  double force_dir_step_rms_deg = 0, force_dir_step_max_deg = 0;
  double force_dir_step_max_t_s = 0;  ///< time of the largest direction step [s]
  /// Ticks of the stroke phase (script t_stroke <= t < t_lift) and how many of them were in
  /// contact: a stroke that stays on the surface it starts on has a share near 1.
  long stroke_ticks = 0, stroke_contact_ticks = 0;
  /// The hand path's plan (script.plan: "ray" or "surface", run/scene_script.h): the press
  /// depth of the hand's target [m]; for "surface" also its least along the stroke [m], the depth the force allows [m], the
  /// thinnest wall under the stroke [m] (+inf: none thin enough to bind) and the stroke's
  /// length walked on the surface [m].
  std::string plan = "ray";
  double plan_press_depth_m = 0, plan_min_press_depth_m = 0, plan_force_depth_m = 0, plan_stroke_length_m = 0;
  double plan_min_wall_m = std::numeric_limits<double>::infinity();
  /// Contact ticks whose |F| is under 0.95 of the force limit (the rest sit at the limit).
  long contact_ticks_under_95pct_limit = 0;
  /// The lift-off (t >= script t_lift): contact ticks and the largest |F| [N] while the hand
  /// pulls the probe back out (a clean retraction has few and small).
  long lift_contact_ticks = 0;
  double lift_max_force_n = 0;
  /// Of those, the ticks whose force pushes into the object (against the outward normal at
  /// the first contact: the hole "grabs" the probe) and the largest such component [N].
  long lift_inward_ticks = 0;
  double lift_max_inward_force_n = 0;
  /// With filters in the pass list: distance [m] of the VHIP from the isosurface of the
  /// unfiltered data (gradient only), RMS and max over the contact ticks with a surface
  /// found: what smoothing moves the felt surface away from the data. has_unfiltered false
  /// without filters.
  bool has_unfiltered = false;
  double unfiltered_err_rms_m = 0, unfiltered_err_max_m = 0;
  /// The scene's edits (present = false without an "edits" section).
  EditFigures edits;
  /// The force's rate limits in the servo and the device, with how many ticks each bound:
  /// the edit ease (the force step of an edit eased out over edit_period_s: its largest
  /// rate |step| / period [N/s], and the lag it adds, a breakthrough included: the period),
  /// the release fade (recovery_time_s > 0: a contact ended with force on fades over it),
  /// the device's own clip at its maximum force. No direction limit exists (0 deg/s cap).
  long edit_ease_ticks = 0;
  double edit_ease_max_rate_n_s = 0, edit_period_s = 0;
  long release_fade_ticks = 0;
  long device_clipped_ticks = 0;
  /// The drilling ripple: amplitude [N] of the sent |F| at the edit frequency (1 / edit
  /// period) over the drilling phase (runs of at least 3 published brush edits one edit
  /// period apart), after removing a moving median one edit period long; < 0: no drilling
  /// phase. ripple_ticks: the ticks it was measured over.
  double ripple_n = -1;
  long ripple_ticks = 0;
};

}  // namespace isotouch::run
