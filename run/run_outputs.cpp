#include "isotouch/run/run_outputs.h"
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
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
#include "isotouch/eval/drill_channel.h"
#include "isotouch/materials/label_export.h"
#include "isotouch/materials/label_volume.h"
#include "isotouch/run/channel_section.h"
#include "isotouch/run/drill_figure.h"
#include "isotouch/run/names.h"
#include "isotouch/run/picture.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/run/text.h"

namespace isotouch::run {
namespace fs = std::filesystem;
namespace {

// edits.png: |F| with the drill threshold, HIP / VHIP depth below the initial contact point,
// removed volume; button intervals shaded, brush applications marked.
bool draw_edit_plots(const Scene& scene, const std::string& dir, const sim::TouchScript& script,
                     const engine::Volume& vol, std::string& note) {
  const std::string csv = fs::absolute(fs::path(dir) / "trace.csv").string();
  const std::string ecsv = fs::absolute(fs::path(dir) / "edits.csv").string();
  const std::string png = fs::absolute(fs::path(dir) / "edits.png").string();
  const Vec3 c = vol.to_physical(script.contact_point_m), n = vol.direction_apply(script.contact_normal);
  std::ostringstream depth;  // depth [mm] of trace.csv columns (x, y, z) below the contact point along -n
  depth << std::setprecision(12);
  auto dexpr = [&](int col) {
    std::ostringstream e;
    e << std::setprecision(12) << "(1000*((" << c.x << "-$" << col << ")*(" << n.x << ")+(" << c.y << "-$" << col + 1
      << ")*(" << n.y << ")+(" << c.z << "-$" << col + 2 << ")*(" << n.z << ")))";
    return e.str();
  };
  std::ostringstream g;
  g << "# Edit plots of " << dir << "; re-run with: gnuplot edits.gp\n"
    << "set datafile separator ','\n"
    << "set terminal pngcairo size 1100,980 font 'Sans,10'\n"
    << "set output " << gnuplot_quote(temp_name(png)) << "\n"
    << "set multiplot layout 3,1 title " << gnuplot_quote("isotouch - " + scene.name + ": force, depth and removed volume while editing") << "\n"
    << "set grid\nset key top left\nset xrange [0:" << script.duration_s << "]\n";
  int obj = 1;
  for (const auto& iv : scene.edits.button_down)
    g << "set object " << obj++ << " rect from " << iv[0] << ", graph 0 to " << iv[1]
      << ", graph 1 fc rgb '#fdebd0' fs solid 0.6 behind\n";
  g << "set ylabel '|F| [N]'\n"
    << "plot " << gnuplot_quote(csv) << " every ::1 using 1:(sqrt($8**2+$9**2+$10**2)) with lines lw 1.5 lc rgb '#c0392b' title '|F| on the device', "
    << gnuplot_quote(ecsv) << " every ::1 using 1:($8 > 0 ? $9 : 1/0) with points pt 7 ps 0.35 lc rgb '#1e8449' title 'brush applied (force given)', ";
  if (scene.edits.brush.kind == "drill")
    g << scene.edits.brush.force_threshold_n << " with lines dt 3 lc rgb '#1e8449' title 'drill threshold', ";
  g << scene.hri.force_limit_n << " with lines dt 2 lc rgb '#555555' title 'force limit'\n"
    << "set ylabel 'depth [mm]'\n"
    << "plot " << gnuplot_quote(csv) << " every ::1 using 1:" << dexpr(2) << " with lines lw 1.5 lc rgb '#2471a3' title 'HIP depth', "
    << gnuplot_quote(csv) << " every ::1 using 1:" << dexpr(5) << " with lines lw 1.5 lc rgb '#7d3c98' title 'VHIP depth', "
    << "0 with lines dt 2 lc rgb '#555555' title 'initial surface'\n"
    << "set xlabel 't [s]   (orange: button down)'\n"
    << "set ylabel 'removed [mm^3]'\n"
    << "plot " << gnuplot_quote(ecsv) << " every ::1 using 1:15 with steps lw 1.5 lc rgb '#b9770e' title 'removed volume (inside voxels before - now)'\n"
    << "unset multiplot\n";
  note = draw_with_gnuplot((fs::path(dir) / "edits.gp").string(), g.str(), {png});
  return note.empty();
}

// Before and after, cut open through the press axis: the isosurface of `vol` with a clip
// plane that contains the axis (the script's ray through its contact point), seen from the
// removed side, perpendicular to the axis, the axis vertical in the picture. A drilled hole
// through a wall shows as a gap in the cut face. Grid-world [m].
engine::RaycastImage render_section(const Scene& scene, const SceneSetup& setup, const engine::Volume& vol,
                                    const std::string& out_png) {
  const core::Isosurface iso = setup.live.iso;
  const engine::RaycastField rf = engine::make_raycast_field(vol.grid, vol.voxels, iso, setup.live.background);
  const Vec3 axis = core::normalized_or(setup.script.contact_normal * -1.0, Vec3{1, 0, 0});
  // The volume axis least aligned with the press axis gives the side the camera looks from.
  const Vec3 cand[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  Vec3 w = cand[0];
  for (const Vec3& c : cand)
    if (std::abs(dot(c, axis)) < std::abs(dot(w, axis))) w = c;
  const Vec3 side = core::normalized_or(cross(axis, w), Vec3{0, 1, 0});  // camera looks along +side
  const double reach = std::max(scene.script.press_depth_m, 0.01);
  const Vec3 target = setup.script.contact_point_m + axis * (0.5 * reach);
  const double fov = 35, half_width = 1.2 * reach + 0.005;
  const double dist = half_width / std::tan(0.5 * fov * 3.14159265358979 / 180);
  PictureRequest req;
  req.width = 640;
  req.height = 640;
  req.view = engine::look_at(target - side * dist, target, axis * -1.0, fov);
  req.style.clip = engine::ClipPlane{setup.script.contact_point_m, side * -1.0};
  return render_picture(setup.vk.get(), rf, vol.direction, req, out_png);
}

// Drill scenes: the breakthrough and the channel's open radius (EditFigures), and the
// channel's section drawn from the voxels (channel_section.png in `dir`).
void drill_figures(const Scene& scene, const SceneSetup& setup, const std::vector<sim::TraceRow>& trace,
                   const engine::Volume& after, const std::string& dir, EditFigures& e, std::ostream& log) {
  e.drill = true;
  const double tool = setup.hri.tool_radius_m;
  e.burr_radius_m = tool > 0 ? tool : scene.edits.brush.radius_mm * 1e-3;
  e.cut_radius_m = 1e-3 * run::brush_at_tool(scene, setup.volume, scene.edits.brush).radius_mm;
  e.cut_margin_m = e.cut_radius_m - e.burr_radius_m;
  std::vector<double> t, f;
  std::vector<char> down;
  std::vector<Vec3> centres;
  for (const auto& r : trace) {
    t.push_back(r.t_s);
    f.push_back(core::norm(r.force_n));
    down.push_back(r.button ? 1 : 0);
    if (r.button && r.contact) centres.push_back(r.vhip_m);
  }
  const eval::Breakthrough b = eval::find_breakthrough(t, f, down, scene.edits.brush.force_threshold_n);
  e.breakthrough = b.found;
  e.breakthrough_t_s = b.t_s, e.breakthrough_from_n = b.from_n, e.breakthrough_to_n = b.to_n, e.breakthrough_fall_s = b.fall_s;
  const eval::ChannelFigures c = eval::measure_channel(setup.volume, after, setup.live.iso, centres,
                                                       setup.script.contact_normal * -1.0, e.burr_radius_m);
  e.channel_measured = c.measured;
  e.channel_slices = c.slices;
  e.channel_min_open_radius_m = c.min_open_radius_m;
  e.channel_min_at_depth_m = c.min_at_depth_m;
  e.channel_min_fraction = c.min_fraction;
  if (e.breakthrough)
    log << "drill    breakthrough at t = " << fmt(b.t_s, 5) << " s: |F| fell from " << fmt(b.from_n, 4) << " N to "
        << fmt(b.to_n, 4) << " N in " << fmt(b.fall_s * 1e3, 4) << " ms\n";
  else
    log << "drill    no breakthrough (|F| never fell to a tenth of the drill threshold for good while drilling)\n";
  if (c.measured) {
    const ChannelCut cut{c.min_centre_m, setup.script.contact_normal * -1.0, e.burr_radius_m, c.min_open_radius_m};
    e.channel_section_note =
        draw_channel_section(setup.volume, after, setup.live.iso, cut, (fs::path(dir) / "channel_section.png").string());
    e.channel_section_drawn = e.channel_section_note.empty();
    if (!e.channel_section_drawn) log << "drill    channel_section.png not drawn: " << e.channel_section_note << "\n";
  }
  if (c.measured)
    log << "drill    channel: narrowest open radius " << fmt(c.min_open_radius_m * 1e3, 4) << " mm ("
        << fmt(100 * c.min_fraction, 3) << " % of the burr's " << fmt(e.burr_radius_m * 1e3, 4) << " mm) at "
        << fmt(c.min_at_depth_m * 1e3, 4) << " mm along the path, " << c.slices << " slices\n";
}

}  // namespace

bool draw_plots(const Scene& scene, const std::string& dir, const sim::TouchScript& script,
                std::string& note) {
  const std::string csv = fs::absolute(fs::path(dir) / "trace.csv").string();
  const std::string fd = fs::absolute(fs::path(dir) / "force_depth.png").string();
  const std::string tt = fs::absolute(fs::path(dir) / "tick_time.png").string();
  std::ostringstream g;
  g << "# Plots of " << dir << "/trace.csv; re-run with: gnuplot plots.gp\n"
    << "set datafile separator ','\n"
    << "set terminal pngcairo size 1100,760 font 'Sans,10'\n"
    << "set output " << gnuplot_quote(temp_name(fd)) << "\n"
    << "set multiplot layout 2,1 title " << gnuplot_quote("isotouch - " + scene.name + ": HRI force and penetration (simulated device)") << "\n"
    << "set grid\nset key top left\n"
    << "set object 1 rect from " << script.t_press << ", graph 0 to " << script.t_stroke
    << ", graph 1 fc rgb '#eeeeff' fs solid 0.5 behind\n"
    << "set object 2 rect from " << script.t_stroke << ", graph 0 to " << script.t_lift
    << ", graph 1 fc rgb '#eeffee' fs solid 0.5 behind\n"
    << "set ylabel '|F| [N]'\n"
    << "plot " << gnuplot_quote(csv) << " every ::1 using 1:(sqrt($8**2+$9**2+$10**2)) with lines lw 1.5 lc rgb '#c0392b' title '|F| on the device', "
    << scene.hri.force_limit_n << " with lines dt 2 lc rgb '#555555' title 'force limit'\n"
    << "set xlabel 't [s]   (blue: press and hold, green: stroke)'\n"
    << "set ylabel 'penetration [mm]'\n"
    << "plot " << gnuplot_quote(csv) << " every ::1 using 1:(1000*sqrt(($2-$5)**2+($3-$6)**2+($4-$7)**2)) with lines lw 1.5 lc rgb '#2471a3' title '|HIP - VHIP|'\n"
    << "unset multiplot\n"
    << "unset object 1\nunset object 2\n"
    << "set terminal pngcairo size 1100,420 font 'Sans,10'\n"
    << "set output " << gnuplot_quote(temp_name(tt)) << "\n"
    << "set title " << gnuplot_quote("HRI servo tick wall time (this machine, CPU)") << "\n"
    << "set logscale y\nset xlabel 't [s]'\nset ylabel 'tick [ns]'\n"
    << "plot " << gnuplot_quote(csv) << " every ::1 using 1:13 with points pt 7 ps 0.3 lc rgb '#7d3c98' title 'HriRenderer::tick'\n";
  note = draw_with_gnuplot((fs::path(dir) / "plots.gp").string(), g.str(), {fd, tt});
  return note.empty();
}

// The path for a picture, thinned to about 600 ticks (each is an overlay every pixel
// tests: a 6000-tick path takes minutes on lavapipe); the tick of the largest force kept.
std::vector<sim::TraceRow> thin_path(const std::vector<sim::TraceRow>& trace) {
  std::vector<sim::TraceRow> path;
  const std::size_t every = std::max<std::size_t>(1, trace.size() / 600);
  std::size_t fmax = 0;
  for (std::size_t i = 0; i < trace.size(); ++i)
    if (core::norm(trace[i].force_n) > core::norm(trace[fmax].force_n)) fmax = i;
  for (std::size_t i = 0; i < trace.size(); ++i)
    if (i % every == 0 || i == fmax) path.push_back(trace[i]);
  return path;
}

// The figures, files and pictures of a run with edits, into m.edits.
namespace {

// The edit figures of a run: counts and times from the applied events, the undo history,
// the removed volume and the deepest HIP and VHIP.
void edit_figures(const SceneSetup& setup, const EditDriver& d, const std::vector<sim::TraceRow>& trace, EditFigures& e) {
  const long after_edit = e.contact_ticks_after_edit;
  e = d.figures;
  e.contact_ticks_after_edit = after_edit;
  e.present = true;
  EditSession& session = *setup.session;
  for (std::size_t k = 0; k < setup.critical.size(); ++k) {  // each critical material against the volume as loaded
    const std::vector<float>& now = session.volume().voxels;
    const std::vector<std::uint8_t>& ids = setup.cut->ids;
    for (std::size_t i = 0; i < now.size(); ++i)
      if (ids[i] == setup.critical[k].id && std::memcmp(&now[i], &setup.volume.voxels[i], sizeof(float)) != 0)
        ++e.critical[k].voxels_changed;
  }
  e.events = long(d.rows.size());
  std::vector<double> upd, brush_ms;
  for (const EditRow& r : d.rows) {
    if (r.outcome.published) {
      ++e.publications;
      upd.push_back(r.outcome.wall_ms);
      e.update_ms_max = std::max(e.update_ms_max, r.outcome.wall_ms);
      e.recomputed_bricks += long(r.outcome.update.recomputed);
      e.gpu_updates += r.outcome.update.gpu ? 1 : 0;
    }
    if (r.event.kind == EditEvent::Kind::kBrush) {
      e.dirty_bricks += long(r.outcome.brush.dirty.size());
      brush_ms.push_back(r.outcome.brush.wall_ms);
      ++(r.outcome.brush.on_device ? e.brushes_on_device : e.brushes_on_cpu);
    }
  }
  e.update_ms_median = upd.empty() ? 0 : median(upd);  // 0: no edit ran
  e.brush_ms_median = brush_ms.empty() ? 0 : median(brush_ms);
  e.last_version = session.current()->version;
  e.brushes_on_gpu = session.sculptor().on_gpu();
  e.history_bytes = session.sculptor().history().bytes();
  e.history_limit_bytes = session.sculptor().history().limit_bytes();
  e.history_dropped = session.sculptor().history().dropped_strokes();
  const engine::Volume& after = session.volume();
  e.inside_voxels_before = d.inside_before();
  e.inside_voxels_after = inside_voxels(after, setup.live.iso);
  const auto& sp = after.grid.spacing_m;
  e.removed_mm3 = double(e.inside_voxels_before - e.inside_voxels_after) * sp.x * sp.y * sp.z * 1e9;
  const Vec3 cp = setup.script.contact_point_m, n = setup.script.contact_normal;
  for (const auto& r : trace) {
    e.max_hip_depth_m = std::max(e.max_hip_depth_m, core::dot(cp - r.hip_m, n));
    e.max_vhip_depth_m = std::max(e.max_vhip_depth_m, core::dot(cp - r.vhip_m, n));
  }
}

// The edit figures in the log.
void log_edits(const EditFigures& e, std::ostream& log) {
  log << "edits    " << e.brushes << " brush applications (" << e.timeline_brushes << " timeline, " << e.button_brushes
      << " button), " << e.undos << " undo, " << e.redos << " redo; " << e.publications << " snapshots published (last version "
      << e.last_version << "); update median " << fmt(e.update_ms_median, 4) << " ms, max " << fmt(e.update_ms_max, 4)
      << " ms; " << e.gpu_updates << " of " << e.publications << " updates filtered on the GPU\n         " << (e.removed_mm3 < 0 ? "added " : "removed ") << fmt(std::abs(e.removed_mm3), 5) << " mm^3 ("
      << std::abs(e.inside_voxels_before - e.inside_voxels_after) << " voxels); deepest HIP " << fmt(e.max_hip_depth_m * 1e3, 4) << " mm, VHIP " << fmt(e.max_vhip_depth_m * 1e3, 4)
      << " mm below the initial contact point; undo history " << e.history_bytes << " B of " << e.history_limit_bytes
      << " B\n";
  for (const std::string& note : e.notes) log << "edits    note: " << note << "\n";
}

// The mesh written as drilled.stl: closed or not, and the volume it encloses against the
// inside voxels' volume.
void mesh_figures(const io::Mesh& mesh, const engine::Volume& after, EditFigures& e, std::ostream& log) {
  const io::MeshStats st = io::mesh_stats(mesh);
  const auto& sp = after.grid.spacing_m;
  e.mesh_measured = true;
  e.mesh_triangles = st.triangles;
  e.mesh_dropped_triangles = mesh.dropped_triangles;
  e.mesh_boundary_edges = st.boundary_edges;
  e.mesh_nonmanifold_edges = st.nonmanifold_edges;
  e.mesh_closed = st.closed();
  e.mesh_volume_mm3 = st.signed_volume_m3 * 1e9;
  e.inside_voxels_volume_mm3 = double(e.inside_voxels_after) * sp.x * sp.y * sp.z * 1e9;
  log << "edits    drilled.stl: " << st.triangles << " triangles (" << mesh.dropped_triangles
      << " zero-area dropped), " << (st.closed() ? "closed" : "NOT closed") << ", encloses "
      << fmt(e.mesh_volume_mm3, 6) << " mm^3 (inside voxels: " << fmt(e.inside_voxels_volume_mm3, 6) << " mm^3)\n";
}

// The edited volume (.vdb, .nrrd) and its isosurface (.stl) as the scene asks; a failure is
// said in e.files_note, never fatal.
void write_edited_files(const Scene& scene, const SceneSetup& setup, const std::string& dir, io::MeshUnits mesh_units,
                        EditFigures& e, std::ostream& log) {
  const engine::Volume& after = setup.session->volume();
  try {
    if (scene.edits.write_vdb) {
      SaveVdbOptions vo;
      vo.iso = setup.live.iso;
      vo.source_path = setup.volume.path;
      save_vdb(after, (fs::path(dir) / "drilled.vdb").string(), vo);
      e.vdb_file = "drilled.vdb";
    }
    if (scene.edits.write_nrrd) {
      io::save_volume_itk(after, (fs::path(dir) / "drilled.nrrd").string());
      e.nrrd_file = "drilled.nrrd";
    }
    if (setup.labels && (scene.edits.write_vdb || scene.edits.write_nrrd)) {  // beside the saved volume
      materials::write_seg_nrrd((fs::path(dir) / "drilled.seg.nrrd").string(),
                                materials::edited_ids(setup.labels->ids, setup.volume.voxels, after.voxels, setup.live.iso),
                                setup.labels->materials, after);
      e.seg_file = "drilled.seg.nrrd";
    }
    if (scene.edits.write_stl) {
      const io::Mesh mesh = extract_mesh(after, setup.live.iso);
      write_stl_binary(mesh, (fs::path(dir) / "drilled.stl").string(), mesh_units);
      e.stl_file = "drilled.stl";
      e.stl_units = io::to_string(mesh_units);
      mesh_figures(mesh, after, e, log);
    }
  } catch (const std::exception& x) {
    e.files_note = x.what();
    log << "edits    file not written: " << x.what() << "\n";
  }
}

// Before and after: surface.png's camera on the unedited and the edited volume, the sections
// through the press axis, drill.png and edits.png.
void edit_pictures(const Scene& scene, const SceneSetup& setup, const std::vector<sim::TraceRow>& trace,
                   const std::string& dir, bool surface_drawn, EditFigures& e, std::ostream& log) {
  const engine::Volume& after = setup.session->volume();
  // Before and after: the same camera (from the run's contact points), unedited and edited voxels.
  const std::vector<sim::TraceRow> path = thin_path(trace);
  // before.png: surface.png when it was drawn (the same volume, snapshot and path).
  RunPicture before;
  bool copied = false;
  if (surface_drawn) {
    try {  // through the one writer, like every output
      io::write_output((fs::path(dir) / "before.png").string(), [&](const std::string& f) {
        fs::copy_file(fs::path(dir) / "surface.png", f, fs::copy_options::overwrite_existing);
      });
      copied = true;
    } catch (const std::exception&) {
    }
  }
  if (!copied)
    before = render_run_picture(scene, setup.volume, *setup.first, path, (fs::path(dir) / "before.png").string(),
                                setup.vk.get(), setup.device);
  const RunPicture aft = render_run_picture(scene, after, *setup.session->current(), path,
                                            (fs::path(dir) / "after.png").string(), setup.vk.get(), setup.device);
  e.before_after_drawn = before.error.empty() && aft.error.empty();
  try {
    render_section(scene, setup, setup.volume, (fs::path(dir) / "section_before.png").string());
    render_section(scene, setup, after, (fs::path(dir) / "section_after.png").string());
    e.sections_drawn = true;
  } catch (const std::exception& x) {
    e.sections_note = x.what();
  }
  const DrillSite site{setup.script.contact_point_m, setup.script.contact_normal, scene.edits.brush.radius_mm * 1e-3};
  e.site_figure_note = draw_drill_figure(setup.vk.get(), setup.volume, after, setup.live.iso, site,
                                         (fs::path(dir) / "drill.png").string());
  e.site_figure_drawn = e.site_figure_note.empty();
  if (!e.site_figure_drawn) log << "edits    drill.png not drawn: " << e.site_figure_note << "\n";
  e.before_after_note = e.before_after_drawn ? aft.caption : before.error + " " + aft.error;
  if (scene.write_trace) {
    std::string note;
    e.plot_drawn = draw_edit_plots(scene, dir, setup.script, setup.volume, note);
    if (!e.plot_drawn) {
      e.before_after_note += " plots: " + note;
      log << "edits    plot not drawn: " << note << "\n";
    }
  }
}

}  // namespace

void finish_edits(const Scene& scene, SceneSetup& setup, const EditDriver& d, const std::vector<sim::TraceRow>& trace,
                  const std::string& dir, io::MeshUnits mesh_units, RunMetrics& m, std::ostream& log) {
  EditFigures& e = m.edits;
  edit_figures(setup, d, trace, e);
  if (scene.edits.brush.kind == "drill") drill_figures(scene, setup, trace, setup.session->volume(), dir, e, log);
  log_edits(e, log);
  write_file_atomic((fs::path(dir) / "edits.csv").string(), edits_csv(d.rows, setup.volume));
  write_edited_files(scene, setup, dir, mesh_units, e, log);
  if (scene.draw_plots) edit_pictures(scene, setup, trace, dir, m.picture_drawn, e, log);
}

}  // namespace isotouch::run
