#include "isotouch/run/run_report.h"
#include "isotouch/run/stroke_warning.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>
#include "isotouch/run/names.h"
#include "isotouch/run/text.h"

namespace isotouch::run {
namespace fs = std::filesystem;
namespace {

std::vector<std::string> pass_labels(const std::vector<engine::PassDesc>& passes) {
  std::vector<std::string> out;
  for (const auto& p : passes) out.push_back(p.label());
  return out;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

nlohmann::ordered_json figures_json(const std::vector<PassFigure>& f) {
  nlohmann::ordered_json a = nlohmann::ordered_json::array();
  for (const auto& p : f)
    a.push_back({{"label", p.label}, {"ms", p.ms >= 0 ? nlohmann::ordered_json(p.ms) : nlohmann::ordered_json(nullptr)},
                 {"dispatches", p.dispatches}});
  return a;
}

// summary.json "engine": the scene's passes with their parameters, what ran (GPU, CPU)
// and what was left out, the snapshot's mode, format, bricks and bytes.
nlohmann::ordered_json engine_json(const RunMetrics& m) {
  nlohmann::ordered_json passes = nlohmann::ordered_json::array();
  for (const auto& p : m.passes) {
    nlohmann::ordered_json e = {{"kind", engine::pass_name(p.kind)}, {"label", p.label()}};
    if (p.kind == engine::PassKind::Gaussian) e["sigma_mm"] = p.sigma_mm;
    if (p.kind == engine::PassKind::Closing) e["radius_mm"] = p.radius_mm;
    if (p.kind == engine::PassKind::BrickMinMax) e["halo"] = p.halo;
    passes.push_back(e);
  }
  const auto or_null = [](bool have, auto v) { return have ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); };
  return {{"mode", m.engine_mode},
          {"samples", m.sample_format},
          {"passes", passes},
          {"gpu", m.engine_ran},
          {"sparse_fallback", or_null(!m.engine_fallback.empty(), m.engine_fallback)},
          {"cpu_reference", m.reference_ran},
          {"gpu_passes", figures_json(m.gpu_passes)},
          {"cpu_passes", figures_json(m.cpu_passes)},
          {"upload_ms", m.gpu_upload_ms},
          {"submit_wall_ms", m.gpu_submit_wall_ms},
          {"download_ms", m.gpu_download_ms},
          {"publish_ms", m.publish_ms},
          {"describe", lines_of(m.engine_describe)},
          {"bricks", {{"total", or_null(m.bricks_total > 0, m.bricks_total)},
                      {"candidates", or_null(m.bricks_total > 0, m.bricks_candidates)},
                      {"active", or_null(m.bricks_total > 0, m.bricks_active)}}},
          {"snapshot_bytes", m.snapshot_bytes},
          {"dense_fp32_bytes", m.dense_fp32_bytes},
          {"snapshot_fraction_of_dense_fp32",
           m.dense_fp32_bytes ? double(m.snapshot_bytes) / double(m.dense_fp32_bytes) : 0.0}};
}

std::string pass_list_text(const std::vector<engine::PassDesc>& passes) {
  std::string s;
  for (const auto& p : passes) s += (s.empty() ? "" : " -> ") + p.label();
  return s;
}

// report.md "## Engine": the passes that ran (GPU and CPU ms), what was left out, the snapshot.
std::string engine_markdown(const RunMetrics& m) {
  std::ostringstream md;
  md << "## Engine\n\n"
     << "Mode **" << m.engine_mode << "**, samples **" << m.sample_format << "**. Published snapshot computed by "
     << m.engine_ran << "; CPU reference: " << m.reference_ran << ".";
  if (!m.engine_fallback.empty())
    md << " The sparse GPU chain was not used (" << m.engine_fallback
       << "): the dense chain's samples were converted to bricks instead.";
  md << "\n\n| stage | GPU [ms] | dispatches |\n|---|---|---|\n";
  for (const auto& p : m.gpu_passes)
    md << "| " << p.label << " | " << (p.ms >= 0 ? fmt(p.ms, 4) : std::string("no timestamps")) << " | " << p.dispatches
       << " |\n";
  md << "\n| CPU reference stage | CPU [ms] (one thread) |\n|---|---|\n";
  for (const auto& p : m.cpu_passes) md << "| " << p.label << " | " << fmt(p.ms, 4) << " |\n";
  md << "\nUpload " << fmt(m.gpu_upload_ms, 4) << " ms, submit to fence " << fmt(m.gpu_submit_wall_ms, 4)
     << " ms, download " << fmt(m.gpu_download_ms, 4) << " ms" << (m.publish_ms > 0 ? ", publish " + fmt(m.publish_ms, 4) + " ms" : "")
     << " (wall clock).\n\n";
  if (m.bricks_total)
    md << "Bricks (8^3 voxels): " << m.bricks_total << " in all, " << m.bricks_candidates << " computed (candidates), "
       << m.bricks_active << " published with samples (" << fmt(100.0 * double(m.bricks_active) / double(m.bricks_total), 3)
       << " %). ";
  md << "Snapshot " << m.snapshot_bytes << " B against " << m.dense_fp32_bytes << " B for the dense fp32 snapshot ("
     << fmt(100.0 * double(m.snapshot_bytes) / double(std::max<std::uint64_t>(1, m.dense_fp32_bytes)), 3) << " %).\n\n"
     << "Pipelines and buffers created and left out:\n\n```\n" << m.engine_describe << "\n```\n\n";
  return md.str();
}

// The report's row for drilled.stl: closed or not, and its enclosed volume.
std::string mesh_row(const EditFigures& e) {
  if (!e.mesh_measured) return "";
  std::ostringstream md;
  md << "| " << e.stl_file << " | " << e.mesh_triangles << " triangles (" << e.mesh_dropped_triangles
     << " zero-area triangles dropped), "
     << (e.mesh_closed ? std::string("**closed** (every edge in exactly two triangles)")
                       : "**not closed**: " + std::to_string(e.mesh_boundary_edges) + " edges in one triangle, " +
                             std::to_string(e.mesh_nonmanifold_edges) + " in three or more")
     << "; encloses " << fmt(e.mesh_volume_mm3, 6) << " mm^3 (the inside voxels after the edits: "
     << fmt(e.inside_voxels_volume_mm3, 6) << " mm^3";
  if (e.inside_voxels_volume_mm3 > 0)
    md << ", " << fmt(100.0 * (e.mesh_volume_mm3 / e.inside_voxels_volume_mm3 - 1.0), 3) << " %";
  md << ") |\n";
  return md.str();
}

// The report's rows for the breakthrough and the channel.
std::string drill_rows(const EditFigures& e, const Scene& scene) {
  if (!e.drill) return "";
  std::ostringstream md;
  md << "| breakthrough | ";
  if (e.breakthrough)
    md << "**t = " << fmt(e.breakthrough_t_s, 5) << " s**: |F| fell from " << fmt(e.breakthrough_from_n, 4) << " N to "
       << fmt(e.breakthrough_to_n, 4) << " N in " << fmt(e.breakthrough_fall_s * 1e3, 4) << " ms (to a tenth of the "
       << fmt(scene.edits.brush.force_threshold_n, 4) << " N drill threshold, staying there while the button is down) |\n";
  else
    md << "none: |F| never fell to a tenth of the " << fmt(scene.edits.brush.force_threshold_n, 4)
       << " N drill threshold for good while the button was down |\n";
  md << "| cutting brush | radius " << fmt(e.cut_radius_m * 1e3, 4) << " mm: "
     << (scene.hri.tool_radius_m > 0 ? "the spherical tool's " + fmt(e.burr_radius_m * 1e3, 4) + " mm plus " +
                                            fmt(e.cut_margin_m * 1e3, 4) + " mm (half the largest voxel spacing)"
                                      : std::string("felt as a point (servo.tool.point)"))
     << " |\n";
  md << "| channel | ";
  if (e.channel_measured)
    md << "narrowest open radius **" << fmt(e.channel_min_open_radius_m * 1e3, 4) << " mm = "
       << fmt(100 * e.channel_min_fraction, 3) << " %** of the burr's " << fmt(e.burr_radius_m * 1e3, 4) << " mm, at "
       << fmt(e.channel_min_at_depth_m * 1e3, 4) << " mm along the burr's path (" << e.channel_slices
       << " slices a quarter voxel apart where the burr centre passed through material) |\n";
  else
    md << "not measured: the burr centre never passed through material |\n";
  return md.str();
}

// summary.json edits.critical_margin: one entry per critical material.
nlohmann::ordered_json critical_json(const EditFigures& e) {
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const EditFigures::CriticalFigures& c : e.critical)
    list.push_back(nlohmann::ordered_json{{"name", c.name},
                    {"margin_mm", c.margin_m * 1e3},
                    {"entries", c.entries},
                    {"time_inside_s", c.time_inside_s},
                    {"closest_approach_mm", std::isfinite(c.closest_approach_m) ? nlohmann::ordered_json(c.closest_approach_m * 1e3)
                                                                                : nlohmann::ordered_json(nullptr)},
                    {"first_entry_t_s", c.first_entry_t_s >= 0 ? nlohmann::ordered_json(c.first_entry_t_s)
                                                               : nlohmann::ordered_json(nullptr)},
                    {"voxels_changed", c.voxels_changed}});
  return {{"materials", list},
          {"method", "per critical material, every tick: distance from the centre of the brush cutting that tick (a "
                     "timeline drill or carve, else the button drill at the VHIP) to the nearest voxel centre of that "
                     "material (exact distance transform, lower bound between voxel centres) minus that brush's radius, "
                     "against that material's margin_mm"}};
}

nlohmann::ordered_json edits_json(const EditFigures& e, const Scene& scene) {
  const nlohmann::ordered_json drill =
      !e.drill ? nlohmann::ordered_json(nullptr)
               : nlohmann::ordered_json{
                     {"burr_radius_mm", e.burr_radius_m * 1e3},
                     {"probe", scene.hri.tool_radius_m > 0 ? "sphere" : "point"},
                     {"cut_radius_mm", e.cut_radius_m * 1e3},
                     {"cut_margin_mm", e.cut_margin_m * 1e3},
                     {"breakthrough", !e.breakthrough ? nlohmann::ordered_json(nullptr)
                                                      : nlohmann::ordered_json{{"t_s", e.breakthrough_t_s},
                                                                               {"from_n", e.breakthrough_from_n},
                                                                               {"to_n", e.breakthrough_to_n},
                                                                               {"fall_s", e.breakthrough_fall_s}}},
                     {"channel", !e.channel_measured ? nlohmann::ordered_json(nullptr)
                                                     : nlohmann::ordered_json{{"slices", e.channel_slices},
                                                                              {"min_open_radius_mm", e.channel_min_open_radius_m * 1e3},
                                                                              {"min_at_depth_mm", e.channel_min_at_depth_m * 1e3},
                                                                              {"min_fraction_of_burr", e.channel_min_fraction}}}};
  const auto or_null = [](bool have, auto v) { return have ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); };
  return {{"brush", {{"kind", scene.edits.brush.kind}, {"radius_mm", scene.edits.brush.radius_mm},
                     {"force_threshold_n", scene.edits.brush.force_threshold_n}, {"rate_value_per_n_s", e.drill_rate_value_per_n_s},
                     {"removal_per_n_s", e.drill_removal_per_n_s}}},
          {"every_ticks", scene.edits.every_ticks},
          {"drill", drill},
          {"brushes_on", e.brushes_on_gpu ? "GPU" : "CPU"},
          {"brush_applications_on_device", e.brushes_on_device},
          {"brush_applications_on_cpu", e.brushes_on_cpu},
          {"events", e.events},
          {"brush_applications", e.brushes},
          {"timeline_applications", e.timeline_brushes},
          {"button_applications", e.button_brushes},
          {"undo", e.undos},
          {"redo", e.redos},
          {"snapshots_published", e.publications},
          {"last_version", e.last_version},
          {"first_edit_t_s", or_null(e.first_edit_t_s >= 0, e.first_edit_t_s)},
          {"dirty_bricks", e.dirty_bricks},
          {"recomputed_bricks", e.recomputed_bricks},
          {"update_ms", {{"median", e.update_ms_median}, {"max", e.update_ms_max},
                         {"what", "EditSession::apply wall time (brush + live field update + publish), publishing events"}}},
          {"brush_ms_median", e.brush_ms_median},
          {"history_bytes", e.history_bytes},
          {"history_limit_bytes", e.history_limit_bytes},
          {"history_dropped_strokes", e.history_dropped},
          {"removed_mm3", std::max(0.0, e.removed_mm3)},
          {"added_mm3", std::max(0.0, -e.removed_mm3)},
          {"did_nothing", {{"undo_with_nothing_to_undo", e.undo_nothing},
                           {"redo_with_nothing_to_redo", e.redo_nothing},
                           {"brushes_changing_no_voxel", e.brushes_changing_nothing},
                           {"of_which_outside_the_volume", e.brushes_outside},
                           {"vhip_brushes_before_contact", e.vhip_before_contact},
                           {"timeline_entries_after_the_end", e.timeline_after_end},
                           {"notes", e.notes}}},
          {"inside_voxels", {{"before", e.inside_voxels_before}, {"after", e.inside_voxels_after}}},
          {"removed_method", "(inside voxels of the raw volume before - after) x voxel volume; inside = the scene's isovalue and inside, NaN outside"},
          {"max_hip_depth_m", e.max_hip_depth_m},
          {"max_vhip_depth_m", e.max_vhip_depth_m},
          {"depth_method", "distance below the initial contact point along the inward surface normal there (the press direction)"},
          {"contact_ticks_after_edit", e.contact_ticks_after_edit},
          {"vdb", or_null(!e.vdb_file.empty(), e.vdb_file)},
          {"nrrd", or_null(!e.nrrd_file.empty(), e.nrrd_file)},
          {"seg_nrrd", or_null(!e.seg_file.empty(), e.seg_file)},
          {"stl", or_null(!e.stl_file.empty(), e.stl_file)},
          {"files_note", e.files_note},
          {"mesh", !e.mesh_measured ? nlohmann::ordered_json(nullptr)
                                    : nlohmann::ordered_json{{"file", e.stl_file},
                                                             {"units", e.stl_units},
                                                             {"space", "LPS"},
                                                             {"triangles", e.mesh_triangles},
                                                             {"zero_area_triangles_dropped", e.mesh_dropped_triangles},
                                                             {"closed", e.mesh_closed},
                                                             {"boundary_edges", e.mesh_boundary_edges},
                                                             {"nonmanifold_edges", e.mesh_nonmanifold_edges},
                                                             {"enclosed_volume_mm3", e.mesh_volume_mm3},
                                                             {"inside_voxels_volume_mm3", e.inside_voxels_volume_mm3},
                                                             {"method", "closed: every edge in exactly two triangles; "
                                                                        "enclosed volume by the divergence theorem (> 0: normals out)"}}},
          {"pictures", [&e] {
             nlohmann::ordered_json a = nlohmann::ordered_json::array();
             if (e.site_figure_drawn) a.push_back("drill.png");
             if (e.before_after_drawn) a.insert(a.end(), {"before.png", "after.png"});
             if (e.sections_drawn) a.insert(a.end(), {"section_before.png", "section_after.png"});
             if (e.channel_section_drawn) a.push_back("channel_section.png");
             return a;
           }()},
          {"plot", e.plot_drawn ? nlohmann::ordered_json("edits.png") : nlohmann::ordered_json(nullptr)},
          {"critical_margin", e.critical.empty() ? nlohmann::ordered_json(nullptr) : critical_json(e)},
          {"csv", "edits.csv"}};
}

namespace {
// The margin warning's rows, one per critical material: entries, time inside, closest approach.
std::string margin_row(const EditFigures& e) {
  std::ostringstream r;
  for (const EditFigures::CriticalFigures& c : e.critical)
    r << "| critical margin | " << c.name << ", margin " << fmt(c.margin_m * 1e3, 4) << " mm: "
      << (c.entries ? "**WARNING** " : "") << c.entries << " entr" << (c.entries == 1 ? "y" : "ies") << ", "
      << fmt(c.time_inside_s, 4) << " s inside, closest approach "
      << (std::isfinite(c.closest_approach_m) ? fmt(c.closest_approach_m * 1e3, 4) + " mm" : std::string("none"))
      << " (the cutting brush's surface); " << c.voxels_changed << " of its voxels changed |\n";
  return r.str();
}
}  // namespace

std::string edits_markdown(const EditFigures& e, const Scene& scene) {
  std::ostringstream md;
  const BrushSpec& b = scene.edits.brush;
  md << "## Edits\n\n"
     << "Brush **" << b.kind << "**, radius " << fmt(b.radius_mm, 4) << " mm"
     << (b.kind == "drill" ? ", threshold " + fmt(b.force_threshold_n, 4) + " N, rate " + fmt(e.drill_removal_per_n_s, 4) +
                                 " of the material-to-empty range per N s (" + fmt(e.drill_rate_value_per_n_s, 6) + " value units per N s)"
                           : std::string())
     << ", applied every " << scene.edits.every_ticks << " servo ticks while the button is down and the probe is in contact"
     << " (brushes on the " << (e.brushes_on_gpu ? "GPU" : "CPU") << ": " << e.brushes_on_device
     << " application(s) on the device, " << e.brushes_on_cpu << " on the CPU reference).\n\n"
     << "| | |\n|---|---|\n"
     << "| applications | " << e.brushes << " (" << e.timeline_brushes << " from the timeline, " << e.button_brushes
     << " from the button); " << e.undos << " undo, " << e.redos << " redo; " << e.events << " events in all |\n"
     << "| snapshots | " << e.publications << " published, last version " << e.last_version << " |\n"
     << "| bricks | " << e.dirty_bricks << " dirty (summed over applications), " << e.recomputed_bricks << " recomputed |\n"
     << "| update time | median " << fmt(e.update_ms_median, 4) << " ms, max " << fmt(e.update_ms_max, 4)
     << " ms (EditSession::apply: brush, live field update, publish; wall clock, this machine); brush median "
     << fmt(e.brush_ms_median, 4) << " ms |\n"
     << (e.removed_mm3 < 0 ? "| added volume | **" : "| removed volume | **") << fmt(std::abs(e.removed_mm3), 5)
     << " mm^3** (" << e.inside_voxels_before << " inside voxels before, " << e.inside_voxels_after
     << " after, times the voxel volume) |\n"
     << "| depth below the initial surface | HIP " << fmt(e.max_hip_depth_m * 1e3, 4) << " mm, VHIP "
     << fmt(e.max_vhip_depth_m * 1e3, 4) << " mm (deepest, along the press direction from the first contact point) |\n"
     << drill_rows(e, scene) << mesh_row(e) << margin_row(e)
     << "| undo history | " << e.history_bytes << " B of the " << e.history_limit_bytes << " B limit ("
     << e.history_dropped << " strokes dropped) |\n"
     << "| surface error | every contact tick against the volume whose snapshot it read; " << e.contact_ticks_after_edit
     << " contact ticks read an edited snapshot (dense samples of the edited volume rebuilt per snapshot) |\n\n";
  if (!e.notes.empty()) {
    md << "Edits that did nothing:\n\n";
    for (const std::string& n : e.notes) md << "- " << n << "\n";
    md << "\n";
  }
  if (e.site_figure_drawn)
    md << "![before (left) and after (right): the site from outside, ringed in orange (2 brush radii), zoomed "
          "in the framed inset](drill.png)\n\nBefore (left) and after (right), seen from outside along the surface "
          "normal at the first contact; the orange ring (radius 2 brush radii) marks the site, the framed inset shows "
          "it up close.\n\n";
  else if (!e.site_figure_note.empty())
    md << "drill.png: not drawn (" << e.site_figure_note << ").\n\n";
  if (e.channel_section_drawn)
    md << "![the channel cut open at its narrowest slice: across (left) and along (right)](channel_section.png)\n\n"
          "The channel cut open at its narrowest slice, from the voxels after drilling: across it (left) and along it "
          "(right, the drilling direction down), 5 burr radii wide. Bone-white: material after drilling; orange: "
          "removed by the drill; dark: empty before. Green: the burr's radius; red: the narrowest open radius "
          "measured.\n\n";
  else if (!e.channel_section_note.empty())
    md << "channel_section.png: not drawn (" << e.channel_section_note << ").\n\n";
  if (e.plot_drawn) md << "![force, depth and removed volume against time](edits.png)\n\n";
  if (e.before_after_drawn)
    md << "| before | after |\n|---|---|\n| ![before](before.png) | ![after](after.png) |\n\n";
  if (e.sections_drawn)
    md << "Cut open through the press axis (clip plane containing it, seen from the side; the probe came from "
          "the top):\n\n| section before | section after |\n|---|---|\n"
          "| ![section before](section_before.png) | ![section after](section_after.png) |\n\n";
  else if (!e.sections_note.empty())
    md << "Sections: not drawn (" << e.sections_note << ").\n\n";
  else if (!e.before_after_note.empty())
    md << "Pictures: not drawn (" << e.before_after_note << ").\n\n";
  md << "Files: `edits.csv` (one row per event)"
     << (e.vdb_file.empty() ? std::string() : ", `" + e.vdb_file + "` (the edited volume, OpenVDB FloatGrid)")
     << (e.nrrd_file.empty() ? std::string() : ", `" + e.nrrd_file + "` (the same as NRRD, for 3D Slicer)")
     << (e.seg_file.empty() ? std::string()
                            : ", `" + e.seg_file + "` (the label map after the edits, removed voxels 0: a 3D Slicer segmentation)")
     << (e.stl_file.empty() ? std::string() : ", `" + e.stl_file + "` (its isosurface, binary STL, LPS in " + e.stl_units + ")")
     << (e.files_note.empty() ? std::string() : "; not written: " + e.files_note) << ".\n\n";
  return md.str();
}

}  // namespace

// "finite values [lo, hi]" plus the NaN/Inf counts; never a range for no finite voxels.
std::string value_range_text(const engine::Volume& vol, const RunMetrics& m) {
  std::ostringstream s;
  if (vol.finite_voxels == 0) s << "no finite voxels";
  else s << "finite values [" << vol.min_value << ", " << vol.max_value << "]";
  s << ", " << m.nan_voxels << " NaN and " << m.inf_voxels << " Inf voxels";
  return s.str();
}

std::string direction_text(const std::array<double, 9>& d) {
  std::ostringstream s;
  s << std::setprecision(4) << "[[" << d[0] << ", " << d[1] << ", " << d[2] << "], [" << d[3] << ", " << d[4]
    << ", " << d[5] << "], [" << d[6] << ", " << d[7] << ", " << d[8] << "]]";
  return s.str();
}

// summary.json "volume": the file, its grid, values and frame.
nlohmann::ordered_json volume_json(const engine::Volume& vol, const RunMetrics& m) {
  const bool any_finite = vol.finite_voxels > 0;
  return {{"path", m.volume_path},
          {"dims", m.dims},
          {"spacing_m", {m.spacing_m.x, m.spacing_m.y, m.spacing_m.z}},
          {"reader", vol.reader},
          {"component_type", vol.component_type},
          {"value_range", any_finite ? nlohmann::ordered_json{vol.min_value, vol.max_value}
                                     : nlohmann::ordered_json(nullptr)},
          {"nan_voxels", m.nan_voxels},
          {"inf_voxels", m.inf_voxels},
          {"orientation", m.orientation},
          {"direction", m.direction},
          {"frame", "points and forces are physical (ITK's LPS frame): world = origin + direction * (spacing * index)"}};
}

// summary.json "servo": the renderer, its parameters and tick times.
nlohmann::ordered_json servo_json(const servo::HriParams& hp, const RunMetrics& m) {
  const bool paper = hp.variant == servo::Variant::kPaper;
  return {{"algorithm", paper ? "HRI, the paper's Figure 2 as printed" : "HRI, robust variant (Figure 2 plus the departures in servo/hri.h)"},
          {"variant", paper ? "paper" : "robust"},
          {"rate_hz", hp.rate_hz},
          {"plane_update_period", hp.plane_update_period},
          {"stiffness_n_per_m", hp.stiffness_n_per_m},
          {"damping_n_s_per_m", hp.damping_n_s_per_m},
          {"force_limit_n", hp.force_limit_n},
          {"intersection", hp.intersection == servo::Intersection::kLinear ? "linear"
                           : hp.intersection == servo::Intersection::kSecant ? "secant" : "bisection"},
          {"normal", hp.normal == servo::NormalSource::kSamples ? "samples"
                     : hp.normal == servo::NormalSource::kCentral ? "central" : "exact"},
          {"force_shading", hp.force_shading},
          {"recovery_time_s", hp.recovery_time_s},
          {"tool_radius_mm", hp.tool_radius_m * 1e3},
          {"friction", {{"mu_s", hp.friction.mu_s}, {"mu_d", hp.friction.mu_d},
                        {"viscous_n_s_per_m", hp.friction.viscous_n_s_per_m}}},
          {"ticks", m.ticks},
          {"plane_updates", m.plane_updates},
          {"tick_ns", {{"median", m.tick_ns_median}, {"p99", m.tick_ns_p99},
                       {"max", m.tick_ns_max}, {"mean", m.tick_ns_mean}}}};
}

// summary.json "contact": forces, their steps, saturation, the stiffness bound, faults.
// summary.json "contact.rate_limits": every limit on the force's rate of change, its rate
// and how many ticks it bound (the step figures above are those of the force the device took).
nlohmann::ordered_json rate_limits_json(const RunMetrics& m, const servo::HriParams& hp) {
  const double fade_rate = hp.recovery_time_s > 0 ? hp.force_limit_n / hp.recovery_time_s : 0.0;
  return {{"edit_ease", {{"period_s", m.edit_period_s},
                         {"max_rate_n_per_s", m.edit_ease_max_rate_n_s},
                         {"ticks", m.edit_ease_ticks},
                         {"breakthrough_lag_s", m.edit_period_s},
                         {"why", "an edit's force step eased out over the time its material took to remove"}}},
          {"release_fade", {{"time_s", hp.recovery_time_s}, {"max_rate_n_per_s", fade_rate}, {"ticks", m.release_fade_ticks}}},
          {"device_clip", {{"ticks", m.device_clipped_ticks}}},
          {"direction_limit_deg_per_s", nullptr}};
}

nlohmann::ordered_json contact_json(const RunMetrics& m, const servo::HriParams& hp) {
  return {{"ticks", m.contact_ticks},
          {"max_force_n", m.max_force_n},
          {"mean_force_n", m.mean_contact_force_n},
          {"max_penetration_m", m.max_penetration_m},
          {"max_force_step_n", m.max_force_step_n},
          {"max_force_step_t_s", m.max_force_step_t_s},
          {"max_force_vector_step_n", m.max_force_vector_step_n},
          {"max_force_vector_step_t_s", m.max_force_vector_step_t_s},
          {"max_release_step_n", m.max_release_step_n},
          {"max_release_step_t_s", m.max_release_step_t_s},
          {"max_any_step_n", m.max_any_step_n},
          {"max_any_step_t_s", m.max_any_step_t_s},
          {"max_direction_step_deg", m.force_dir_step_max_deg},
          {"max_direction_step_t_s", m.force_dir_step_max_t_s},
          {"force_direction_step_deg", {{"rms", m.force_dir_step_rms_deg}, {"max", m.force_dir_step_max_deg}}},
          {"saturated_ticks", m.saturated_ticks},
          {"ticks_under_95pct_limit", m.contact_ticks_under_95pct_limit},
          {"fraction_under_95pct_limit", m.contact_ticks ? nlohmann::ordered_json(double(m.contact_ticks_under_95pct_limit) / double(m.contact_ticks))
                                                         : nlohmann::ordered_json(nullptr)},
          {"stiffness_bound_n_per_m", m.k_bound_n_per_m},
          {"stiffness_above_bound", m.k_above_bound},
          {"fault_ticks", m.fault_ticks},
          {"rate_limits", rate_limits_json(m, hp)},
          {"edit_ripple_n", m.ripple_n >= 0 ? nlohmann::ordered_json(m.ripple_n) : nlohmann::ordered_json(nullptr)},
          {"edit_ripple_fraction_of_limit",
           m.ripple_n >= 0 ? nlohmann::ordered_json(m.ripple_n / hp.force_limit_n) : nlohmann::ordered_json(nullptr)},
          {"edit_ripple_ticks", m.ripple_ticks}};
}

// The first-order estimate beside the true distance, on the ticks where it is a distance
// (finite, within the volume's diagonal); the ticks left out and why.
std::string first_order_sentence(const RunMetrics& m) {
  const std::string why = "|grad f| near 0 made it infinite or longer than the volume's diagonal (" +
                          fmt(m.first_order_bound_m * 1e3, 4) + " mm), no distance";
  if (m.first_order_kept_ticks == 0)
    return "The first-order estimate |f - tau| / |grad f| is left out: on every contact tick " + why + ".";
  std::string s = "The first-order estimate |f - tau| / |grad f| would have said RMS " +
                  fmt(m.first_order_err_rms_m * 1e3, 4) + " mm, max " + fmt(m.first_order_err_max_m * 1e3, 4) + " mm";
  if (m.first_order_left_out_ticks > 0)
    s += " on " + std::to_string(m.first_order_kept_ticks) + " contact ticks (" +
         std::to_string(m.first_order_left_out_ticks) + " left out: " + why + ")";
  return s + ".";
}

// summary.json "error": the VHIP's true distance from the isosurface (and from the unfiltered
// data's), and the first-order estimate beside it; null where nothing was measured.
nlohmann::ordered_json error_json(const RunMetrics& m, const servo::HriParams& hp, long found, long raw_found) {
  // No contact tick (or no surface found): there is no error to report, not an error of 0.
  const auto or_null = [](bool have, double v) { return have ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); };
  const std::string tool = hp.tool_radius_m > 0
                               ? "; with the spherical tool (radius " + fmt(hp.tool_radius_m * 1e3) +
                                     " mm) the VHIP is its centre and the error is that of its surface: |distance - r|, "
                                     "distance + r where the centre is inside the object"
                               : std::string();
  return {{"surface_distance_m", {{"rms", or_null(found > 0, m.surface_err_rms_m)}, {"max", or_null(found > 0, m.surface_err_max_m)},
                                  {"ticks_without_surface_within_radius", m.surface_err_not_found_ticks},
                                  {"search_radius_m", m.surface_search_radius_m},
                                  {"measured_on", "the dense fp32 samples of the scene's passes (CPU reference): "
                                                  "the published isosurface for dense and bricked fp32, the surface "
                                                  "before rounding for compact samples; a tick that read an edited "
                                                  "snapshot against the edited volume it read"},
                                  {"method", "true distance from the VHIP to the isosurface of the trilinear field "
                                             "(branch and bound over cells, error below min(1e-3 voxel, max(1e-6 voxel, 1 % of the distance)))" +
                                             tool}}},
          {"surface_distance_to_unfiltered_m",
           {{"rms", or_null(m.has_unfiltered && raw_found > 0, m.unfiltered_err_rms_m)},
            {"max", or_null(m.has_unfiltered && raw_found > 0, m.unfiltered_err_max_m)},
            {"method", "with filters in the pass list: true distance from the VHIP to the isosurface of the "
                       "unfiltered data (gradient only); null without filters"}}},
          {"first_order_estimate_m", {{"rms", or_null(m.first_order_kept_ticks > 0, m.first_order_err_rms_m)},
                                      {"max", or_null(m.first_order_kept_ticks > 0, m.first_order_err_max_m)},
                                      {"ticks_left_out", m.first_order_left_out_ticks},
                                      {"bound_m", m.first_order_bound_m},
                                      {"method", "|f(VHIP) - tau| / |grad f(VHIP)|: not a distance, unbounded "
                                                 "where the field is flat; shown for comparison only, on the contact "
                                                 "ticks where it is finite and at most bound_m (the volume's diagonal)"}}}};
}

// summary.json "script.plan": how the hand path was made (run/scene_script.h).
nlohmann::ordered_json plan_json(const RunMetrics& m) {
  const auto finite_or_null = [](double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); };
  nlohmann::ordered_json j{{"kind", m.plan}, {"press_depth_m", m.plan_press_depth_m}};
  if (m.plan != "surface") return j;
  j["min_press_depth_m"] = m.plan_min_press_depth_m;
  j["force_depth_m"] = m.plan_force_depth_m;
  j["min_wall_m"] = finite_or_null(m.plan_min_wall_m);
  j["stroke_length_m"] = m.plan_stroke_length_m;
  return j;
}

// summary.json "script": the contact point and normal (physical), the phases, stroke and lift-off.
nlohmann::ordered_json script_json(const engine::Volume& vol, const sim::TouchScript& script, const RunMetrics& m) {
  const Vec3 contact_phys = vol.to_physical(script.contact_point_m);
  const Vec3 normal_phys = vol.direction_apply(script.contact_normal);
  return {{"contact_point_m", {contact_phys.x, contact_phys.y, contact_phys.z}},
          {"contact_normal", {normal_phys.x, normal_phys.y, normal_phys.z}},
          {"duration_s", script.duration_s},
          {"phases_s", {{"press", script.t_press}, {"stroke", script.t_stroke}, {"lift", script.t_lift}}},
          {"stroke_ticks", m.stroke_ticks},
          {"stroke_contact_ticks", m.stroke_contact_ticks},
          {"stroke_contact_fraction", m.stroke_ticks ? nlohmann::ordered_json(double(m.stroke_contact_ticks) / double(m.stroke_ticks))
                                                     : nlohmann::ordered_json(nullptr)},
          {"stroke_contact_warning", stroke_contact_warning(m).empty() ? nlohmann::ordered_json(nullptr)
                                                                       : nlohmann::ordered_json(stroke_contact_warning(m))},
          {"plan", plan_json(m)},
          {"lift_contact_ticks", m.lift_contact_ticks},
          {"lift_max_force_n", m.lift_max_force_n},
          {"lift_inward_ticks", m.lift_inward_ticks},
          {"lift_max_inward_force_n", m.lift_max_inward_force_n}};
}

// The run's summary.json ("status": "complete": written last, once every other output is whole).
nlohmann::ordered_json summary_json(const Scene& scene, const SceneSetup& setup, const RunMetrics& m, long found,
                                    long raw_found, bool with_edits) {
  const engine::Volume& vol = setup.volume;
  const servo::HriParams& hp = setup.hri;
  nlohmann::ordered_json j;
  j["status"] = "complete";
  j["scene"] = {{"file", scene.file}, {"name", scene.name}};
  j["volume"] = volume_json(vol, m);
  j["isovalue"] = hp.tau;
  j["inside"] = hp.inside == core::InsideIs::kAbove ? "above" : "below";
  j["gpu"] = {{"device", m.gpu_device},
              {"device_type", m.gpu_device_type},
              {"passes", pass_labels(m.passes)},
              {"gradient_ms", m.gpu_gradient_ms},
              {"gradient_ms_source", m.gpu_timestamps ? "gpu-timestamps" : "wall-clock"},
              {"submit_wall_ms", m.gpu_submit_wall_ms},
              {"upload_ms", m.gpu_upload_ms},
              {"download_ms", m.gpu_download_ms},
              {"slabs", m.gpu_slabs}};
  j["cpu"] = {{"gradient_ms", m.cpu_gradient_ms}};
  j["engine"] = engine_json(m);
  j["gpu_vs_cpu"] = {{"gradient_max_abs_diff", m.max_abs_diff},
                     {"gradient_max_abs_diff_xyz", m.max_abs_diff_xyz},
                     {"gradient_max_rel_diff", m.max_rel_diff}};
  j["servo"] = servo_json(hp, m);
  j["contact"] = contact_json(m, hp);
  j["error"] = error_json(m, hp, found, raw_found);
  j["script"] = script_json(vol, setup.script, m);
  j["picture"] = {{"file", m.picture_drawn ? nlohmann::ordered_json("surface.png") : nlohmann::ordered_json(nullptr)},
                  {"note", m.picture_note}};
  j["overview"] = {{"file", m.overview_drawn ? nlohmann::ordered_json("overview.png") : nlohmann::ordered_json(nullptr)},
                   {"note", m.overview_note}};
  j["plots"] = m.plots_drawn ? nlohmann::ordered_json::array({"force_depth.png", "tick_time.png"})
                             : nlohmann::ordered_json::array();
  if (with_edits) j["edits"] = edits_json(m.edits, scene);
  return j;
}

// report.md's table: the volume, the Vulkan device and the engine.
std::string volume_rows(const RunMetrics& m, const engine::Volume& vol, const servo::HriParams& hp) {
  std::ostringstream md;
  md << "| | |\n|---|---|\n"
     << "| volume | `" << m.volume_path << "` (" << m.dims[0] << " x " << m.dims[1] << " x " << m.dims[2]
     << ", spacing " << fmt(m.spacing_m.x * 1e3) << " x " << fmt(m.spacing_m.y * 1e3) << " x "
     << fmt(m.spacing_m.z * 1e3) << " mm, " << vol.component_type << "; " << value_range_text(vol, m) << ") |\n"
     << "| orientation | " << m.orientation << ", direction " << direction_text(m.direction)
     << "; reported points and forces are physical (ITK's LPS frame: origin + D (spacing * index)) |\n"
     << "| isovalue | " << fmt(hp.tau) << " (inside: value " << (hp.inside == core::InsideIs::kAbove ? ">" : "<")
     << " isovalue) |\n"
     << (m.cpu_backend ? "| engine device | " : "| Vulkan device | ") << m.gpu_device << " (" << m.gpu_device_type << ") |\n"
     << "| engine | " << m.engine_mode << " mode, " << m.sample_format << " samples, passes "
     << pass_list_text(m.passes) << "; snapshot " << m.snapshot_bytes << " B ("
     << fmt(100.0 * double(m.snapshot_bytes) / double(std::max<std::uint64_t>(1, m.dense_fp32_bytes)), 3)
     << " % of the dense fp32 " << m.dense_fp32_bytes << " B)"
     << (m.bricks_total ? ", " + std::to_string(m.bricks_active) + " of " + std::to_string(m.bricks_total) + " bricks active"
                        : std::string())
     << (m.engine_fallback.empty() ? std::string() : "; **sparse chain not used: " + m.engine_fallback + "**")
     << " (details below) |\n"
     << (m.engine_mode == "sparse" ? (m.cpu_backend ? "| engine stages (sum) | " : "| GPU stages (sum) | ") : "| gradient pass | ") << (m.cpu_backend ? "CPU backend " : "GPU ") << fmt(m.gpu_gradient_ms, 4) << " ms ("
     << (m.gpu_timestamps ? "GPU timestamps" : "wall clock") << ", " << m.gpu_slabs << " slab(s)); CPU reference "
     << fmt(m.cpu_gradient_ms, 4) << " ms (one thread) |\n"
     << (m.cpu_backend ? "| CPU backend vs CPU reference gradient | max abs " : "| GPU vs CPU gradient | max abs ") << fmt(m.max_abs_diff, 3)
     << "; relative (to the largest gradient magnitude) " << fmt(m.max_rel_diff, 3) << " |\n";
  return md.str();
}

// report.md's table: the servo, its ticks, the stroke, the lift-off and the stiffness bound.
std::string servo_rows(const RunMetrics& m, const servo::HriParams& hp) {
  const bool paper = hp.variant == servo::Variant::kPaper;
  std::ostringstream md;
  md << "| servo | K = " << fmt(hp.stiffness_n_per_m) << " N/m, B = " << fmt(hp.damping_n_s_per_m)
     << " N s/m, n = " << hp.plane_update_period << ", " << fmt(hp.rate_hz) << " Hz, force limit "
     << fmt(hp.force_limit_n) << " N, " << (paper ? "paper" : "robust") << " variant, force shading "
     << (hp.force_shading ? "on" : "off") << ", recovery time " << fmt(hp.recovery_time_s * 1e3) << " ms"
     << (hp.tool_radius_m > 0 ? ", spherical tool of radius " + fmt(hp.tool_radius_m * 1e3) +
                                    " mm (the VHIP is its centre; brushes at the VHIP take its radius + the largest voxel spacing)"
                              : std::string(", point tool"))
     << " |\n"
     << "| ticks | " << m.ticks << " (" << m.contact_ticks << " in contact, " << m.plane_updates
     << " plane updates, " << m.saturated_ticks << " saturated, " << m.fault_ticks << " faults) |\n"
     << "| tick wall time | median " << fmt(m.tick_ns_median) << " ns, p99 " << fmt(m.tick_ns_p99)
     << " ns, max " << fmt(m.tick_ns_max) << " ns |\n"
     << "| stroke | " << (m.stroke_ticks ? std::to_string(m.stroke_contact_ticks) + " of " + std::to_string(m.stroke_ticks) +
                              " stroke ticks in contact (" + fmt(100.0 * double(m.stroke_contact_ticks) / double(m.stroke_ticks), 3) + " %)"
                        : std::string("no stroke in the script"))
     << "; hand path planned by \"" << m.plan << "\", the hand's target " << fmt(m.plan_press_depth_m * 1e3, 4)
     << " mm under the surface; " << m.contact_ticks_under_95pct_limit << " of " << m.contact_ticks
     << " contact ticks under 0.95 of the force limit |\n"
     << "| lift-off | " << m.lift_contact_ticks << " contact ticks while the hand pulls the probe out, largest |F| "
     << fmt(m.lift_max_force_n, 4) << " N; " << m.lift_inward_ticks
     << " of them pull the probe into the object (largest inward component " << fmt(m.lift_max_inward_force_n, 4)
     << " N) |\n"
     << "| stiffness bound | K = " << fmt(hp.stiffness_n_per_m, 4) << " N/m, Colgate-Schenkel K_max = 2 (b - |B|) / T = "
     << fmt(m.k_bound_n_per_m, 4) << " N/m" << (m.k_above_bound ? " (ABOVE the bound: the contact may buzz)" : "")
     << " |\n";
  return md.str();
}

// report.md's table: contact forces, their steps and the surface error.
std::string contact_rows(const RunMetrics& m, const servo::HriParams& hp, long found, long raw_found) {
  std::ostringstream md;
  md << "| contact | max force " << fmt(m.max_force_n, 4) << " N, mean " << fmt(m.mean_contact_force_n, 4)
     << " N, max penetration " << fmt(m.max_penetration_m * 1e3, 4) << " mm |\n"
     << "| largest force step in contact | " << fmt(m.max_force_step_n, 4) << " N at t = "
     << fmt(m.max_force_step_t_s, 5) << " s (" << fmt(100 * m.max_force_step_n / hp.force_limit_n, 3)
     << " % of the force limit) |\n"
     << "| largest release step | " << fmt(m.max_release_step_n, 4) << " N at t = " << fmt(m.max_release_step_t_s, 5)
     << " s (" << fmt(100 * m.max_release_step_n / hp.force_limit_n, 3)
     << " % of the force limit; |F| on a contact tick whose next tick has no contact) |\n"
     << "| largest force vector step in contact | " << fmt(m.max_force_vector_step_n, 4) << " N at t = "
     << fmt(m.max_force_vector_step_t_s, 5) << " s (" << fmt(100 * m.max_force_vector_step_n / hp.force_limit_n, 3)
     << " % of the force limit; |F_k - F_k-1| between contact ticks) |\n"
     << "| largest force step, any ticks | " << fmt(m.max_any_step_n, 4) << " N at t = " << fmt(m.max_any_step_t_s, 5)
     << " s (" << fmt(100 * m.max_any_step_n / hp.force_limit_n, 3) << " % of the force limit) |\n"
     << "| force rate limits | edit ease over " << fmt(m.edit_period_s * 1e3, 4) << " ms (the time an edit's material took to remove; largest rate "
     << fmt(m.edit_ease_max_rate_n_s, 4) << " N/s, " << m.edit_ease_ticks << " ticks eased, a breakthrough felt at most "
     << fmt(m.edit_period_s * 1e3, 4) << " ms late); release fade " << m.release_fade_ticks << " ticks"
     << (hp.recovery_time_s > 0 ? " (over " + fmt(hp.recovery_time_s * 1e3, 4) + " ms)" : std::string(" (off)"))
     << "; device clip " << m.device_clipped_ticks << " ticks; no direction limit. Steps are those of the force the device took |\n"
     << (m.ripple_n >= 0 ? "| edit ripple | " + fmt(m.ripple_n, 4) + " N (" + fmt(100 * m.ripple_n / hp.force_limit_n, 3) +
                               " % of the force limit): the sent |F| at the edit frequency over " + std::to_string(m.ripple_ticks) +
                               " drilling ticks, after a moving median one edit period long |\n"
                         : std::string())
     << "| largest force direction step | " << fmt(m.force_dir_step_max_deg, 3) << " deg at t = "
     << fmt(m.force_dir_step_max_t_s, 5) << " s (RMS " << fmt(m.force_dir_step_rms_deg, 3)
     << " deg; angle between the forces of consecutive contact ticks) |\n"
     << (m.has_unfiltered && raw_found > 0
             ? "| distance from the unfiltered data's surface | RMS " + fmt(m.unfiltered_err_rms_m * 1e3, 4) + " mm, max " +
                   fmt(m.unfiltered_err_max_m * 1e3, 4) + " mm (how far the filters moved the felt surface) |\n"
             : std::string())
     << (hp.tool_radius_m > 0 ? "| surface error of the tool's surface | " : "| surface error of the VHIP | ")
     << (found == 0 ? std::string(m.contact_ticks == 0 ? "not known: no contact tick" : "not known: no surface found")
                    : std::string(hp.tool_radius_m > 0 ? "|true distance of its centre (the VHIP) to the trilinear isosurface - r|"
                                                       : "true distance to the trilinear isosurface") + ": RMS " + fmt(m.surface_err_rms_m * 1e3, 4) + " mm, max " +
                          fmt(m.surface_err_max_m * 1e3, 4) + " mm (" +
                          fmt(m.surface_err_rms_m / std::min({m.spacing_m.x, m.spacing_m.y, m.spacing_m.z}), 3) +
                          " voxel RMS)")
     << (m.surface_err_not_found_ticks
                               ? "; " + std::to_string(m.surface_err_not_found_ticks) +
                                     " contact ticks with no surface within " + fmt(m.surface_search_radius_m * 1e3, 4) +
                                     " mm (left out of RMS and max)"
                               : std::string())
     << " |\n\n";
  return md.str();
}

// The run's report.md.
std::string report_markdown(const Scene& scene, const SceneSetup& setup, const RunMetrics& m, long found,
                            long raw_found, bool with_edits) {
  const engine::Volume& vol = setup.volume;
  const servo::HriParams& hp = setup.hri;
  const bool paper = hp.variant == servo::Variant::kPaper;
  std::ostringstream md;
  md << "# isotouch run: " << scene.name << "\n\n";
  if (!scene.description.empty()) md << scene.description << "\n\n";
  md << "A simulated point-mass device, pulled by a scripted operator hand, approaches the isosurface, "
        "presses in, strokes along it and lifts off. Forces come from the HRI servo (intermediate "
        "virtual plane, "
     << (paper ? "the paper's Figure 2 as printed" : "robust variant: the paper's Figure 2 plus the departures listed in servo/hri.h")
     << ") reading the sample field that the Vulkan gradient pass wrote.\n\n";
  md << volume_rows(m, vol, hp) << servo_rows(m, hp) << contact_rows(m, hp, found, raw_found);
  if (const std::string w = stroke_contact_warning(m); !w.empty()) md << "**Warning: " << w << ".**\n\n";
  md << (m.fault_ticks == 0
             ? std::string("No faults: every tick had a finite HIP and a finite force.\n\n")
             : "**Faults: " + std::to_string(m.fault_ticks) + " of " + std::to_string(m.ticks) + " ticks (" +
                   fmt(100.0 * double(m.fault_ticks) / double(std::max(1L, m.ticks)), 3) +
                   " %) were faults (non-finite or implausible HIP, or a non-finite force); zero force was sent on those ticks.**\n\n");
  if (m.contact_ticks == 0)
    md << "**No contact: the probe never touched the isosurface, so there is no surface error to report "
          "(null in summary.json). Check the isovalue, the volume's spacing and the script.**\n\n";
  else if (found == 0)
    md << "**No surface was found within " << fmt(m.surface_search_radius_m * 1e3, 4)
       << " mm of the VHIP on any contact tick: the surface error is not known (null in summary.json).**\n\n";
  else
  md << "## Error against run time\n\nAt a median tick of " << fmt(m.tick_ns_median) << " ns (p99 "
     << fmt(m.tick_ns_p99) << " ns) with the plane recomputed every " << hp.plane_update_period
     << " ticks, " << (hp.tool_radius_m > 0 ? "the tool's surface (radius " + fmt(hp.tool_radius_m * 1e3, 4) + " mm about the VHIP)"
                                           : std::string("the VHIP"))
     << " stayed within " << fmt(m.surface_err_max_m * 1e3, 4)
     << " mm of the trilinear isosurface (RMS " << fmt(m.surface_err_rms_m * 1e3, 4) << " mm) on the "
     << m.contact_ticks - m.surface_err_not_found_ticks << " contact ticks where a surface was found. "
     << first_order_sentence(m) << "\n\n";
  if (with_edits) md << edits_markdown(m.edits, scene);
  md << engine_markdown(m);
  if (m.overview_drawn)
    md << "## Overview\n\n![the whole object, the probe's path](overview.png)\n\n" << m.overview_note << "\n\n";
  else if (!m.overview_note.empty())
    md << "Overview: " << m.overview_note << "\n\n";
  if (m.picture_drawn)
    md << "## Where the probe touched\n\n![isosurface, probe path and contact points](surface.png)\n\n"
       << m.picture_note << "\n\n";
  else if (!m.picture_note.empty())
    md << "Picture: not drawn (" << m.picture_note << ").\n\n";
  if (m.plots_drawn)
    md << "## Force and penetration\n\n![force and penetration against time](force_depth.png)\n\n"
       << "## Servo tick time\n\n![tick wall time](tick_time.png)\n\n";
  else
    md << "Plots: " << m.plot_note << ".\n\n";
  md << "Files: `trace.csv` (one row per tick), `summary.json`, `plots.gp` (gnuplot script for the plots).\n";
  return md.str();
}

nlohmann::ordered_json passivity_json(const std::optional<servo::PassivityStats>& stats) {
  if (!stats) return {{"status", "not run"}, {"note", "no servo thread: nothing was observed"}};
  const servo::PassivityStats& p = *stats;
  return {{"status", "run"},
          {"control", p.control},
          {"clock", p.device_clock ? "device" : "servo"},
          {"energy_in_j", p.energy_in_j},
          {"energy_out_j", p.energy_out_j},
          {"dissipated_j", p.dissipated_j},
          {"active_ticks", p.active_ticks},
          {"restarts", p.restarts}};
}

}  // namespace isotouch::run
