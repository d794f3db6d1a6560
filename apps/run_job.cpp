#include "run_job.h"

#include <csignal>

#include "drill_channel.h"
#include "drill_figure.h"
#include "output_file.h"
#include "volume_write.h"
#include "run_folder.h"
#include "stop_signal.h"

#include <nlohmann/json.hpp>
#include <unistd.h>

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

#include "stats.h"
#include "stability.h"
#include "brick_field.h"
#include "brush.h"
#include "live_session.h"
#include "record.h"
#include "vdb_io.h"
#include "cpu_gradient.h"
#include "field_view.h"
#include "files.h"
#include "passes.h"
#include "render_cmd.h"
#include "sparse_chain.h"
#include "sampling.h"
#include "synthetic.h"
#include "shapes.h"
#include "surface_distance.h"
#include "volume_io.h"
#include "vk_context.h"

namespace isotouch::app {
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
namespace {

namespace fs = std::filesystem;
using core::Vec3;

std::string fmt(double v, int prec = 6) {
  std::ostringstream s;
  s << std::setprecision(prec) << v;
  return s.str();
}

// One row per tick; points and forces in the volume's physical frame
// (world = origin + D (spacing * index)), not the grid frame the servo works in.
std::string trace_csv(const std::vector<sim::TraceRow>& trace, const engine::Volume& vol) {
  std::ostringstream s;
  s << "t_s,hip_x_m,hip_y_m,hip_z_m,vhip_x_m,vhip_y_m,vhip_z_m,f_x_n,f_y_n,f_z_n,contact,"
       "plane_update,tick_ns\n";
  s << std::setprecision(9);
  for (const auto& r : trace) {
    const Vec3 hip = vol.to_physical(r.hip_m), vhip = vol.to_physical(r.vhip_m);
    const Vec3 f = vol.direction_apply(r.force_n);
    s << r.t_s << ',' << hip.x << ',' << hip.y << ',' << hip.z << ',' << vhip.x << ',' << vhip.y << ','
      << vhip.z << ',' << f.x << ',' << f.y << ',' << f.z << ',' << int(r.contact) << ','
      << int(r.plane_update) << ',' << r.tick_ns << '\n';
  }
  return s.str();
}

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

struct EngineRun {
  std::shared_ptr<core::SampleField> published;    ///< what the servo reads (version 1, background set)
  std::shared_ptr<const core::SampleField> truth;  ///< dense fp32 samples of the same passes
};

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

std::vector<PassFigure> figures(const std::vector<engine::PassTiming>& t) {
  std::vector<PassFigure> out;
  for (const auto& p : t) out.push_back({p.label, p.ms, p.dispatches});
  return out;
}

// GPU-vs-CPU figures of two dense sample fields into m.
void compare_into(const core::SampleField& gpu, const core::SampleField& cpu, RunMetrics& m) {
  const engine::GradientDiff diff = engine::compare_gradients(gpu, cpu);
  m.max_abs_diff = diff.max_abs_all;
  m.max_rel_diff = diff.max_rel;
  for (int k = 0; k < 3; ++k) m.max_abs_diff_xyz[k] = diff.max_abs[k];
}

// Dense: PassChain on the GPU (one command buffer), run_chain_cpu as the reference.
EngineRun run_dense(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                    engine::VulkanContext& vk, const RunOptions& opt, float background, RunMetrics& m) {
  auto chain = engine::PassChain::create(vk, passes);
  if (!chain) throw std::runtime_error(vol.path + ": " + chain.error);
  engine::ChainOutput out = (*chain.value)->run(vol, opt.max_binding_bytes);
  m.engine_describe = (*chain.value)->describe();
  m.engine_ran = "PassChain (GPU, dense, one command buffer)";
  if (!out.samples) throw std::runtime_error(vol.path + ": the pass chain returned no samples");
  auto field = std::make_shared<core::SampleField>(std::move(*out.samples));
  field->background = background;
  m.gpu_passes = figures(out.passes);
  m.gpu_upload_ms = out.upload_ms;
  m.gpu_download_ms = out.download_ms;
  m.gpu_submit_wall_ms = out.submit_wall_ms;
  m.gpu_timestamps = out.gpu_timestamps;
  for (const auto& p : out.passes)
    if (p.label == "gradient") {
      m.gpu_gradient_ms = p.ms >= 0 ? p.ms : out.submit_wall_ms;
      m.gpu_slabs = p.dispatches;
    }
  engine::ChainOutput ref = engine::run_chain_cpu(vol, passes);
  m.reference_ran = "run_chain_cpu (one thread, dense)";
  m.cpu_passes = figures(ref.passes);
  for (const auto& p : ref.passes)
    if (p.label == "gradient") m.cpu_gradient_ms = p.ms;
  ref.samples->background = background;
  compare_into(*field, *ref.samples, m);
  m.snapshot_bytes = std::uint64_t(field->samples.size()) * sizeof(core::Sample);
  m.dense_fp32_bytes = vol.grid.voxel_count() * sizeof(core::Sample);
  field->version = 1;
  return {field, field};
}

// The dense samples as the bricked snapshot of `format` (core::bricked_input_from_dense +
// core::make_bricked_field): the stand-in while the sparse chain is not available.
std::shared_ptr<core::SampleField> to_bricks(const core::SampleField& dense, const core::Isosurface& iso,
                                              core::SampleFormat format, RunMetrics& m) {
  auto f = std::make_shared<core::SampleField>(core::make_bricked_field(core::bricked_input_from_dense(dense, iso), format));
  m.engine_ran = "core::bricked_input_from_dense + core::make_bricked_field";
  m.bricks_total = f->bricks->table.size();
  m.bricks_candidates = m.bricks_total;  // every voxel was computed
  m.bricks_active = f->bricks->table.size() - f->bricks->tiles.size();
  m.snapshot_bytes = core::snapshot_bytes(*f);
  return f;
}

// GPU against CPU snapshot, compared where the servo reads them: value and gradient at
// every voxel centre through core::FieldView (dense or bricked, any sample format).
void compare_snapshots(const core::SampleField& gpu, const core::SampleField& cpu, RunMetrics& m) {
  const core::FieldView a(gpu), b(cpu);
  const core::Grid& g = cpu.grid;
  double max_abs[3] = {0, 0, 0}, max_grad = 0;
  const double inf = std::numeric_limits<double>::infinity();
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Vec3 w = g.to_world(Vec3{double(i), double(j), double(k)});
        const core::FieldValue x = a.value_gradient(w), y = b.value_gradient(w);
        const double dx[3] = {x.gradient.x - y.gradient.x, x.gradient.y - y.gradient.y, x.gradient.z - y.gradient.z};
        for (int c = 0; c < 3; ++c) {
          const double d = std::isnan(dx[c]) ? (std::isnan((&x.gradient.x)[c]) == std::isnan((&y.gradient.x)[c]) ? 0 : inf)
                                             : std::abs(dx[c]);
          max_abs[c] = std::max(max_abs[c], d);
        }
        const double gn = core::norm(y.gradient);
        if (std::isfinite(gn)) max_grad = std::max(max_grad, gn);
      }
  m.max_abs_diff = std::max({max_abs[0], max_abs[1], max_abs[2]});
  for (int c = 0; c < 3; ++c) m.max_abs_diff_xyz[c] = max_abs[c];
  m.max_rel_diff = max_grad > 0 ? m.max_abs_diff / max_grad : m.max_abs_diff;
}

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


// Sparse: SparseChain on the GPU, run_sparse_cpu as the reference; while either is not
// implemented yet, the dense chain plus a conversion of its samples to bricks stands in
// (and the report says so).
EngineRun run_sparse(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                     engine::VulkanContext& vk, const RunOptions& opt, const core::Isosurface& iso,
                     float background, core::SampleFormat format, RunMetrics& m) {
  // The dense fp32 samples of the same passes: what the errors are measured against.
  const auto t_truth = std::chrono::steady_clock::now();
  engine::ChainOutput dense_ref = engine::run_chain_cpu(vol, passes);
  const double truth_ms = ms_since(t_truth);
  auto truth = std::make_shared<core::SampleField>(std::move(*dense_ref.samples));
  truth->background = background;
  truth->version = 1;
  m.dense_fp32_bytes = vol.grid.voxel_count() * sizeof(core::Sample);

  std::optional<engine::SparseOutput> gpu;
  auto chain = engine::SparseChain::create(vk, passes);
  if (!chain) throw std::runtime_error(vol.path + ": " + chain.error);
  try {
    gpu = (*chain.value)->run(vol, iso, background, format, opt.max_binding_bytes);
    m.engine_ran = "SparseChain (GPU, candidate bricks only)";
  } catch (const engine::VolumeError& e) {
    // Not implemented yet, or a pass list the sparse shader cannot hold (e.g. a wide
    // Gaussian): the dense chain stands in, and the report says why.
    m.engine_fallback = e.what();
  }
  m.engine_describe = (*chain.value)->describe();
  std::shared_ptr<core::SampleField> field;
  if (gpu) {
    field = std::make_shared<core::SampleField>(std::move(gpu->field));
    m.gpu_passes = figures(gpu->passes);
    m.gpu_upload_ms = gpu->upload_ms;
    m.gpu_download_ms = gpu->download_ms;
    m.gpu_submit_wall_ms = gpu->submit_wall_ms;
    m.publish_ms = gpu->publish_ms;
    // GPU stages only (labels "... (GPU)"): the host stages are wall time, reported apart.
    m.gpu_gradient_ms = 0;
    bool any_gpu = false, all_stamped = true;
    for (const auto& p : gpu->passes) {
      if (p.label.size() < 5 || p.label.compare(p.label.size() - 5, 5, "(GPU)") != 0) continue;
      any_gpu = true;
      all_stamped = all_stamped && p.ms >= 0;
      m.gpu_gradient_ms += std::max(0.0, p.ms);
    }
    m.gpu_timestamps = any_gpu && all_stamped;
    if (!m.gpu_timestamps) m.gpu_gradient_ms = gpu->submit_wall_ms;
    m.gpu_slabs = int(gpu->stats.slabs);
    m.bricks_total = gpu->stats.bricks_total;
    m.bricks_candidates = gpu->stats.candidates;
    m.bricks_active = gpu->stats.active;
    m.snapshot_bytes = core::snapshot_bytes(*field);
  } else {
    RunMetrics dm;
    const EngineRun d = run_dense(vol, passes, vk, opt, background, dm);
    m.engine_describe = dm.engine_describe + "\n(sparse chain not used: " + m.engine_fallback + ")";
    m.gpu_passes = dm.gpu_passes;
    m.gpu_upload_ms = dm.gpu_upload_ms;
    m.gpu_download_ms = dm.gpu_download_ms;
    m.gpu_submit_wall_ms = dm.gpu_submit_wall_ms;
    m.gpu_gradient_ms = dm.gpu_gradient_ms;
    m.gpu_slabs = dm.gpu_slabs;
    m.gpu_timestamps = dm.gpu_timestamps;
    const auto t0 = std::chrono::steady_clock::now();
    field = to_bricks(*d.published, iso, format, m);
    m.publish_ms = ms_since(t0);
    m.engine_ran = "PassChain (GPU, dense) + " + m.engine_ran;
  }
  // CPU reference of the published snapshot.
  std::shared_ptr<core::SampleField> ref;
  try {
    engine::SparseOutput cpu = engine::run_sparse_cpu(vol, passes, iso, background, format);
    m.reference_ran = "run_sparse_cpu (one thread, candidate bricks only)";
    m.cpu_passes = figures(cpu.passes);
    ref = std::make_shared<core::SampleField>(std::move(cpu.field));
  } catch (const engine::VolumeError& e) {
    RunMetrics cm;
    m.cpu_passes = figures(dense_ref.passes);
    ref = to_bricks(*truth, iso, format, cm);
    m.reference_ran = "run_chain_cpu (one thread, dense) + " + cm.engine_ran + " (run_sparse_cpu: " + e.what() + ")";
  }
  for (const auto& p : dense_ref.passes)
    if (p.label == "gradient") m.cpu_gradient_ms = p.ms;
  (void)truth_ms;
  compare_snapshots(*field, *ref, m);
  field->version = 1;
  return {field, truth};
}

EngineRun run_engine(const Scene& scene, const engine::Volume& vol, engine::VulkanContext& vk,
                     const RunOptions& opt, RunMetrics& m, std::ostream& log) {
  const std::vector<engine::PassDesc> passes = scene_passes(scene);
  const core::SampleFormat format = scene_sample_format(scene);
  const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
  // Outside the volume is outside the object (core::FieldView's background): from the
  // volume's finite range, the same in both modes (filters stay within that range).
  const float background = float(iso.outside_value(vol.min_value, vol.max_value));
  m.passes = passes;
  m.engine_mode = scene.engine.mode;
  m.sample_format = scene.engine.samples;
  const EngineRun r = scene.engine.mode == "dense"
                          ? run_dense(vol, passes, vk, opt, background, m)
                          : run_sparse(vol, passes, vk, opt, iso, background, format, m);
  log << "engine   " << scene.engine.mode << ", " << m.sample_format << " samples: " << m.engine_ran << "\n";
  if (!m.engine_fallback.empty()) log << "         (sparse GPU chain not used: " << m.engine_fallback << ")\n";
  for (std::size_t i = 0; i < m.gpu_passes.size(); ++i)
    log << "         GPU " << m.gpu_passes[i].label << " " << fmt(m.gpu_passes[i].ms, 4) << " ms ("
        << m.gpu_passes[i].dispatches << " dispatch(es))\n";
  for (const auto& p : m.cpu_passes) log << "         CPU " << p.label << " " << fmt(p.ms, 4) << " ms\n";
  if (m.bricks_total)
    log << "bricks   " << m.bricks_active << " active of " << m.bricks_total << " (" << m.bricks_candidates
        << " candidates computed); snapshot " << m.snapshot_bytes << " B against " << m.dense_fp32_bytes
        << " B dense fp32 (" << fmt(100.0 * double(m.snapshot_bytes) / double(std::max<std::uint64_t>(1, m.dense_fp32_bytes)), 3)
        << " %)\n";
  log << "GPU vs CPU max |difference| " << fmt(m.max_abs_diff, 3) << " (relative " << fmt(m.max_rel_diff, 3)
      << ")\n";
  return r;
}

session::BrushKind brush_kind(const std::string& k) {
  if (k == "add") return session::BrushKind::kAdd;
  if (k == "carve") return session::BrushKind::kCarve;
  if (k == "smooth") return session::BrushKind::kSmooth;
  return session::BrushKind::kDrill;
}

// Every brush of the scene through session::validate, before anything runs.
void check_scene_brushes(const Scene& scene, const engine::Volume& vol) {
  const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
  const session::BrushTargets def = session::default_targets(vol, iso);
  const double dt = scene.edits.every_ticks / scene.hri.rate_hz;
  auto check = [&](const BrushSpec& b, const std::string& field) {
    const std::string why = session::validate(make_brush(b, def, vol.grid.centre_m(), dt, 0.0));
    if (!why.empty()) throw SceneError(scene.file + ": field '" + field + "': " + why);
  };
  check(scene.edits.brush, "edits.brush");
  for (const TimedEdit& t : scene.edits.timeline)
    if (t.kind != "undo" && t.kind != "redo") check(t.brush, "edits.timeline[" + std::to_string(t.index) + "]");
}

// Voxels inside the scene's isosurface (NaN outside).
long inside_voxels(const engine::Volume& vol, const core::Isosurface& iso) {
  long n = 0;
  for (float v : vol.voxels) n += iso.contains(double(v)) ? 1 : 0;
  return n;
}

/// One applied event as edits.csv lists it.
struct EditRow {
  EditEvent event;
  std::string source;     ///< "timeline", "button"
  EditOutcome outcome;
  double removed_mm3 = 0; ///< cumulative removed volume after this event [mm^3]
};

// The scene's edits in a simulated session (LiveSession::run_simulated): the timeline's
// entries are submitted at their tick from the after-tick hook (the API side); the button
// drill at the VHIP is the session's own (servo side). Every applied edit comes back
// through on_applied() with its outcome, for edits.csv and the figures.
class EditDriver {
 public:
  EditDriver(const Scene& scene, SceneSetup& setup)
      : scene_(scene), setup_(setup), iso_(setup.live.iso),
        targets_(session::default_targets(setup.volume, iso_)),
        dt_(scene.edits.every_ticks / scene.hri.rate_hz),
        voxel_mm3_(setup.volume.grid.spacing_m.x * setup.volume.grid.spacing_m.y * setup.volume.grid.spacing_m.z * 1e9),
        inside0_(inside_voxels(setup.volume, iso_)) {
    const EditsSpec& e = scene.edits;
    {
      const session::Brush b = make_brush(e.brush, targets_, {}, dt_, 0);
      const double range = std::abs(double(b.targets.material) - double(b.targets.empty));
      figures.drill_rate_value_per_n_s = b.rate;
      figures.drill_removal_per_n_s = range > 0 ? b.rate / range : 0.0;
    }
    for (std::size_t i = 0; i < e.timeline.size(); ++i) {
      const TimedEdit& t = e.timeline[i];
      const long k0 = edit_tick(t.t_s, scene.hri.rate_hz);
      if (t.kind == "undo" || t.kind == "redo") {
        plan_.push_back({k0, i, t.kind == "undo" ? Plan::kUndo : Plan::kRedo});
      } else if (t.duration_s <= 0) {
        plan_.push_back({k0, i, Plan::kApply});
      } else {
        const long k1 = std::max(k0 + 1, edit_tick(t.t_s + t.duration_s, scene.hri.rate_hz));
        plan_.push_back({k0, i, Plan::kBegin});
        long last = k0;
        for (long k = k0; k < k1; k += e.every_ticks) {
          plan_.push_back({k, i, Plan::kApply});
          last = k;
        }
        plan_.push_back({last, i, Plan::kEnd});
      }
    }
    std::stable_sort(plan_.begin(), plan_.end(), [](const Plan& a, const Plan& b) { return a.tick < b.tick; });
    const double end_s = setup.script.duration_s;
    for (std::size_t i = 0; i < e.timeline.size(); ++i)
      if (e.timeline[i].t_s > end_s) {
        ++figures.timeline_after_end;
        note("edits.timeline[" + std::to_string(i) + "] (" + e.timeline[i].kind + " at t = " + fmt(e.timeline[i].t_s, 4) +
             " s) is after the script's end (" + fmt(end_s, 4) + " s): never applied");
      }
  }

  /// The session's button drill: the scene's brush at the tool, every every_ticks ticks.
  session::ButtonDrill drill() const {
    return {make_brush(at_tool(scene_.edits.brush), targets_, {}, dt_, 0), scene_.edits.every_ticks};
  }

  /// SimulatedRun::after_tick: measures what tick k read, then submits the timeline's
  /// entries due at k (applied before tick k + 1).
  void operator()(session::LiveSession& live, long k, const sim::TraceRow& row) {
    const double t = double(k) / scene_.hri.rate_hz;
    contact_seen_ = contact_seen_ || row.contact;
    if (row.contact && row.version > 1) measure_edited(k, row);
    // What tick k read (before this tick's edits): the release check's inside test.
    hip_inside.push_back(iso_.contains(core::FieldView(*setup_.session->current()).value(row.hip_m)) ? 1 : 0);
    for (; next_ < plan_.size() && plan_[next_].tick <= k; ++next_) {
      const Plan& p = plan_[next_];
      const TimedEdit& te = scene_.edits.timeline[p.entry];
      switch (p.what) {
        case Plan::kUndo: submit(live, k, t, EditEvent::Kind::kUndo, {}); break;
        case Plan::kRedo: submit(live, k, t, EditEvent::Kind::kRedo, {}); break;
        case Plan::kBegin: submit(live, k, t, EditEvent::Kind::kBeginStroke, {}); break;
        case Plan::kEnd: submit(live, k, t, EditEvent::Kind::kEndStroke, {}); break;
        case Plan::kApply: {
          if (te.at_vhip && !contact_seen_ && !row.contact) {
            if (figures.vhip_before_contact++ == 0)
              note("t = " + fmt(t, 4) + " s: edits.timeline[" + std::to_string(p.entry) + "] (" + te.kind +
                   " at \"vhip\") came before any contact: applied at the HIP in free space");
          }
          const Vec3 c = te.at_vhip ? row.vhip_m : setup_.volume.to_grid(te.at_m);
          const double f = te.brush.force_n >= 0 ? te.brush.force_n : core::norm(row.force_n);
          submit(live, k, t, EditEvent::Kind::kBrush, make_brush(te.at_vhip ? at_tool(te.brush) : te.brush, targets_, c, dt_, f));
          ++figures.timeline_brushes;
          break;
        }
      }
    }
  }

  /// LiveSessionConfig::on_applied: one row of edits.csv and the figures.
  void on_applied(const EditEvent& applied, const EditOutcome& outcome, session::EditSource source) {
    if (!outcome.error.empty()) return;  // simulated: the session rethrows; the run fails
    EditEvent e = applied;
    e.tick = std::max(0L, applied.tick - 1);  // edits.csv: the tick after which it was applied
    const EditEvent::Kind kind = e.kind;
    const char* src = source == session::EditSource::kButton ? "button"
                      : source == session::EditSource::kApi  ? "timeline"
                                                              : "end of run";
    EditRow r{e, src, outcome, 0};
    if (kind == EditEvent::Kind::kBrush) {
      ++figures.brushes;
      if (source == session::EditSource::kButton) ++figures.button_brushes;
      if (figures.first_edit_t_s < 0) figures.first_edit_t_s = e.t_s;
    }
    if (kind == EditEvent::Kind::kUndo) ++figures.undos;
    if (kind == EditEvent::Kind::kRedo) ++figures.redos;
    said_if_nothing(kind, e.brush, r.outcome, e.t_s);
    if (r.outcome.published) inside_now_ = inside_voxels(setup_.session->volume(), iso_);
    r.removed_mm3 = double(inside0_ - inside_now_) * voxel_mm3_;
    rows.push_back(std::move(r));
  }

  /// A brush applied at the VHIP: with a spherical tool (servo.tool.radius_mm > 0) the VHIP
  /// is the tool's centre and the brush takes the tool's size, reaching one voxel (the
  /// largest spacing: the surface the burr touches lies within one cell of it) past its
  /// surface, so it removes what the burr's surface touches; a point keeps the scene's radius.
  BrushSpec at_tool(const BrushSpec& b) const { return brush_at_tool(scene_, setup_.volume, b); }

  std::vector<char> hip_inside;  ///< per tick: the HIP inside the snapshot that tick read
  /// Contact ticks that read an edited snapshot: the VHIP's true and first-order distance
  /// to the isosurface of that snapshot's volume (dense fp32 CPU chain of the edited voxels).
  struct EditedDistance {
    SurfaceDistance d;
    double first_order_m = 0;
  };
  std::map<long, EditedDistance> edited_distance;
  std::vector<EditRow> rows;
  EditFigures figures;
  long inside_before() const { return inside0_; }

 private:
  struct Plan {
    long tick;
    std::size_t entry;
    enum What { kBegin, kApply, kEnd, kUndo, kRedo } what;
  };
  static void submit(session::LiveSession& live, long k, double t, EditEvent::Kind kind, const session::Brush& b) {
    EditEvent e;
    e.kind = kind;
    e.tick = k;
    e.t_s = t;
    if (kind == EditEvent::Kind::kBrush) e.brush = b;
    if (!live.submit(e)) throw std::runtime_error("edits: the session's edit queue is full at t = " + fmt(t, 4) + " s");
  }

  /// At tick k (before its edits) the session's volume is the one whose snapshot the tick
  /// read: its dense samples are rebuilt once per snapshot version.
  void measure_edited(long k, const sim::TraceRow& row) {
    if (!truth_ || truth_version_ != row.version) {
      truth_ = std::make_shared<core::SampleField>(
          std::move(*engine::run_chain_cpu(setup_.session->volume(), scene_passes(scene_)).samples));
      truth_->background = setup_.truth->background;
      truth_version_ = row.version;
    }
    edited_distance[k] = {distance_to_isosurface(*truth_, scene_.hri.tau, row.vhip_m),
                          first_order_distance(*truth_, scene_.hri.tau, row.vhip_m)};
  }

  /// One line per kind of edit that did nothing (the first time), into figures.notes.
  void note(const std::string& s) { figures.notes.push_back(s); }
  void said_if_nothing(EditEvent::Kind kind, const session::Brush& b, const EditOutcome& o, double t) {
    const bool undo = kind == EditEvent::Kind::kUndo, redo = kind == EditEvent::Kind::kRedo;
    if ((undo || redo) && o.restored.empty()) {
      long& n = undo ? figures.undo_nothing : figures.redo_nothing;
      if (n++ == 0) note("t = " + fmt(t, 4) + " s: " + (undo ? "undo with nothing to undo" : "redo with nothing to redo"));
    }
    if (kind != EditEvent::Kind::kBrush || !o.brush.dirty.empty()) return;
    ++figures.brushes_changing_nothing;
    const auto& g = setup_.volume.grid;
    const Vec3 lo = g.to_world(Vec3{-0.5, -0.5, -0.5}),
               hi = g.to_world(Vec3{g.dims[0] - 0.5, g.dims[1] - 0.5, g.dims[2] - 0.5});
    const Vec3& c = b.centre_m;
    const double r = b.radius_m;
    const bool outside = c.x + r < lo.x || c.y + r < lo.y || c.z + r < lo.z || c.x - r > hi.x || c.y - r > hi.y || c.z - r > hi.z;
    if (outside && figures.brushes_outside++ == 0)
      note("t = " + fmt(t, 4) + " s: a " + session::to_string(b.kind) + " brush entirely outside the volume changed nothing");
    else if (!outside && figures.brushes_changing_nothing - figures.brushes_outside == 1)
      note("t = " + fmt(t, 4) + " s: a " + session::to_string(b.kind) + " brush changed no voxel (" +
           (b.kind == session::BrushKind::kDrill && !(b.force_n > b.force_threshold_n)
                ? "the force, " + fmt(b.force_n, 3) + " N, was not above the drill's threshold of " + fmt(b.force_threshold_n, 3) + " N"
                : std::string("nothing to remove or add there")) +
           "); " + "later ones are counted in summary.json edits.did_nothing");
  }

  const Scene& scene_;
  SceneSetup& setup_;
  core::Isosurface iso_;
  session::BrushTargets targets_;
  double dt_, voxel_mm3_;
  long inside0_, inside_now_ = inside0_;
  std::vector<Plan> plan_;
  std::size_t next_ = 0;
  std::shared_ptr<core::SampleField> truth_;
  std::uint64_t truth_version_ = 0;
  bool contact_seen_ = false;
};

// edits.csv: one row per applied event, centres physical [mm].
std::string edits_csv(const std::vector<EditRow>& rows, const engine::Volume& vol) {
  std::ostringstream s;
  s << "t_s,tick,event,source,centre_x_mm,centre_y_mm,centre_z_mm,radius_mm,force_n,dirty_bricks,"
       "recomputed_bricks,published,version,apply_ms,removed_mm3\n"
    << std::setprecision(9);
  for (const EditRow& r : rows) {
    const bool brush = r.event.kind == EditEvent::Kind::kBrush;
    const Vec3 c = brush ? vol.to_physical(r.event.brush.centre_m) * 1e3 : Vec3{};
    s << r.event.t_s << ',' << r.event.tick << ',' << (brush ? session::to_string(r.event.brush.kind) : to_string(r.event.kind))
      << ',' << r.source << ',' << c.x << ',' << c.y << ',' << c.z << ',' << (brush ? r.event.brush.radius_m * 1e3 : 0.0)
      << ',' << (brush ? r.event.brush.force_n : 0.0) << ','
      << (brush ? r.outcome.brush.dirty.size() : r.outcome.restored.size()) << ',' << r.outcome.update.recomputed << ','
      << int(r.outcome.published) << ',' << r.outcome.update.version << ',' << r.outcome.wall_ms << ',' << r.removed_mm3
      << '\n';
  }
  return s.str();
}

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

// Drill scenes: the breakthrough and the channel's open radius (EditFigures).
void drill_figures(const Scene& scene, const SceneSetup& setup, const std::vector<sim::TraceRow>& trace,
                   const engine::Volume& after, EditFigures& e, std::ostream& log) {
  e.drill = true;
  const double tool = setup.hri.tool_radius_m;
  e.burr_radius_m = tool > 0 ? tool : scene.edits.brush.radius_mm * 1e-3;
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
  if (c.measured)
    log << "drill    channel: narrowest open radius " << fmt(c.min_open_radius_m * 1e3, 4) << " mm ("
        << fmt(100 * c.min_fraction, 3) << " % of the burr's " << fmt(e.burr_radius_m * 1e3, 4) << " mm) at "
        << fmt(c.min_at_depth_m * 1e3, 4) << " mm along the path, " << c.slices << " slices\n";
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

// The figures, files and pictures of a run with edits, into m.edits.
void finish_edits(const Scene& scene, SceneSetup& setup, const EditDriver& d, const std::vector<sim::TraceRow>& trace,
                  const std::string& dir, RunMetrics& m, std::ostream& log) {
  EditFigures& e = m.edits;
  const long after_edit = e.contact_ticks_after_edit;
  e = d.figures;
  e.contact_ticks_after_edit = after_edit;
  e.present = true;
  EditSession& session = *setup.session;
  e.events = long(d.rows.size());
  std::vector<double> upd, brush_ms;
  for (const EditRow& r : d.rows) {
    if (r.outcome.published) {
      ++e.publications;
      upd.push_back(r.outcome.wall_ms);
      e.update_ms_max = std::max(e.update_ms_max, r.outcome.wall_ms);
      e.recomputed_bricks += long(r.outcome.update.recomputed);
    }
    if (r.event.kind == EditEvent::Kind::kBrush) {
      e.dirty_bricks += long(r.outcome.brush.dirty.size());
      brush_ms.push_back(r.outcome.brush.wall_ms);
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
  if (scene.edits.brush.kind == "drill") drill_figures(scene, setup, trace, after, e, log);
  log << "edits    " << e.brushes << " brush applications (" << e.timeline_brushes << " timeline, " << e.button_brushes
      << " button), " << e.undos << " undo, " << e.redos << " redo; " << e.publications << " snapshots published (last version "
      << e.last_version << "); update median " << fmt(e.update_ms_median, 4) << " ms, max " << fmt(e.update_ms_max, 4)
      << " ms\n         " << (e.removed_mm3 < 0 ? "added " : "removed ") << fmt(std::abs(e.removed_mm3), 5) << " mm^3 ("
      << std::abs(e.inside_voxels_before - e.inside_voxels_after) << " voxels); deepest HIP " << fmt(e.max_hip_depth_m * 1e3, 4) << " mm, VHIP " << fmt(e.max_vhip_depth_m * 1e3, 4)
      << " mm below the initial contact point; undo history " << e.history_bytes << " B of " << e.history_limit_bytes
      << " B\n";
  for (const std::string& note : e.notes) log << "edits    note: " << note << "\n";

  write_file_atomic((fs::path(dir) / "edits.csv").string(), edits_csv(d.rows, setup.volume));
  // The edited volume and its isosurface; a failure is said, never fatal.
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
    if (scene.edits.write_stl) {
      write_stl_binary(extract_mesh(after, setup.live.iso), (fs::path(dir) / "drilled.stl").string());
      e.stl_file = "drilled.stl";
    }
  } catch (const std::exception& x) {
    e.files_note = x.what();
    log << "edits    file not written: " << x.what() << "\n";
  }
  if (scene.draw_plots) {
    // Before and after: the same camera (from the run's contact points), unedited and edited voxels.
    const std::vector<sim::TraceRow> path = thin_path(trace);
    // before.png: surface.png when it was drawn (the same volume, snapshot and path).
    RunPicture before;
    bool copied = false;
    if (m.picture_drawn) {
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
                                  setup.vk.get());
    const RunPicture aft = render_run_picture(scene, after, *session.current(), path,
                                              (fs::path(dir) / "after.png").string(), setup.vk.get());
    e.before_after_drawn = before.error.empty() && aft.error.empty();
    try {
      if (!setup.vk) throw std::runtime_error("no Vulkan device");
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
}

nlohmann::ordered_json edits_json(const EditFigures& e, const Scene& scene) {
  const nlohmann::ordered_json drill =
      !e.drill ? nlohmann::ordered_json(nullptr)
               : nlohmann::ordered_json{
                     {"burr_radius_mm", e.burr_radius_m * 1e3},
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
          {"stl", or_null(!e.stl_file.empty(), e.stl_file)},
          {"files_note", e.files_note},
          {"pictures", [&e] {
             nlohmann::ordered_json a = nlohmann::ordered_json::array();
             if (e.site_figure_drawn) a.push_back("drill.png");
             if (e.before_after_drawn) a.insert(a.end(), {"before.png", "after.png"});
             if (e.sections_drawn) a.insert(a.end(), {"section_before.png", "section_after.png"});
             return a;
           }()},
          {"plot", e.plot_drawn ? nlohmann::ordered_json("edits.png") : nlohmann::ordered_json(nullptr)},
          {"csv", "edits.csv"}};
}

std::string edits_markdown(const EditFigures& e, const Scene& scene) {
  std::ostringstream md;
  const BrushSpec& b = scene.edits.brush;
  md << "## Edits\n\n"
     << "Brush **" << b.kind << "**, radius " << fmt(b.radius_mm, 4) << " mm"
     << (b.kind == "drill" ? ", threshold " + fmt(b.force_threshold_n, 4) + " N, rate " + fmt(e.drill_removal_per_n_s, 4) +
                                 " of the material-to-empty range per N s (" + fmt(e.drill_rate_value_per_n_s, 6) + " value units per N s)"
                           : std::string())
     << ", applied every " << scene.edits.every_ticks << " servo ticks while the button is down and the probe is in contact"
     << " (brushes on the " << (e.brushes_on_gpu ? "GPU" : "CPU") << ").\n\n"
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
     << drill_rows(e, scene)
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
     << (e.stl_file.empty() ? std::string() : ", `" + e.stl_file + "` (its isosurface, binary STL)")
     << (e.files_note.empty() ? std::string() : "; not written: " + e.files_note) << ".\n\n";
  return md.str();
}

}  // namespace

double drill_rate(const BrushSpec& b, const session::BrushTargets& t) {
  if (!(b.removal_per_n_s >= 0)) return b.rate;
  return b.removal_per_n_s * std::abs(double(t.material) - double(t.empty));
}

session::Brush make_brush(const BrushSpec& b, const session::BrushTargets& defaults, const Vec3& centre_m,
                         double dt_s, double force_n) {
  session::Brush e;
  e.kind = brush_kind(b.kind);
  e.centre_m = centre_m;
  e.radius_m = b.radius_mm * 1e-3;
  e.strength = b.strength;
  e.falloff = b.falloff;
  e.targets = defaults;
  if (b.has_material) e.targets.material = float(b.material);
  if (b.has_empty) e.targets.empty = float(b.empty);
  if (b.density_scale > 0) e.targets.density_scale = float(b.density_scale);
  e.force_threshold_n = b.force_threshold_n;
  e.rate = drill_rate(b, e.targets);
  e.dt_s = dt_s;
  e.force_n = force_n;
  return e;
}


io::Recording recording_header(const Scene& scene, const SceneSetup& setup) {
  Recording rec;
  rec.scene_path = fs::absolute(scene.file).string();
  std::ifstream in(scene.file, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  rec.scene_text = text.str();
  rec.rate_hz = setup.hri.rate_hz;
  rec.volume_crc32 = volume_crc32(setup.volume);
  return rec;
}

io::BrushSpec brush_at_tool(const Scene& scene, const engine::Volume& vol, const io::BrushSpec& b) {
  if (!(scene.hri.tool_radius_m > 0)) return b;
  const auto& sp = vol.grid.spacing_m;
  io::BrushSpec t = b;
  t.radius_mm = 1e3 * (scene.hri.tool_radius_m + std::max({sp.x, sp.y, sp.z}));
  return t;
}

std::vector<engine::PassDesc> scene_passes(const Scene& scene) {
  std::vector<engine::PassDesc> out;
  for (const PassSpec& p : scene.engine.passes) {
    if (p.kind == "gaussian") out.push_back(engine::PassDesc::gaussian(p.sigma_mm));
    else if (p.kind == "closing") out.push_back(engine::PassDesc::closing(p.radius_mm));
    else if (p.kind == "gradient") out.push_back(engine::PassDesc::gradient());
    else if (p.kind == "brick_minmax") out.push_back(engine::PassDesc::brick_minmax(p.halo));
    else throw SceneError(scene.file + ": field 'engine.passes': unknown pass \"" + p.kind + "\"");
  }
  if (const std::string e = engine::validate_passes(out); !e.empty())
    throw SceneError(scene.file + ": field 'engine.passes': " + e);
  return out;
}

core::SampleFormat scene_sample_format(const Scene& scene) {
  if (scene.engine.samples == "fp16") return core::SampleFormat::kFp16;
  if (scene.engine.samples == "unorm16") return core::SampleFormat::kUnorm16;
  if (scene.engine.samples == "fp32") return core::SampleFormat::kFp32;
  throw SceneError(scene.file + ": field 'engine.samples': unknown format \"" + scene.engine.samples + "\"");
}

SceneSetup::SceneSetup() = default;
SceneSetup::SceneSetup(SceneSetup&&) noexcept = default;
SceneSetup& SceneSetup::operator=(SceneSetup&&) noexcept = default;
SceneSetup::~SceneSetup() = default;

long edit_tick(double t_s, double rate_hz) { return std::max(0L, long(std::ceil(t_s * rate_hz - 1e-9))); }

SceneSetup setup_scene(const Scene& scene, const RunOptions& opt, std::ostream& log) {
  SceneSetup s;
  RunMetrics& m = s.metrics;
  (void)scene_passes(scene);  // a bad pass list fails before the volume is read
  (void)scene_sample_format(scene);

  // 1. Volume in.
  engine::Volume& vol = s.volume;
  if (!scene.volume_path.empty()) {
    log << "volume   " << scene.volume_path << "\n";
    vol = load_any_volume(scene.volume_path);
  } else if (scene.synthetic.kind == "sphere") {
    vol = engine::make_sphere(scene.synthetic.dims, scene.synthetic.spacing_m, scene.synthetic.radius_vox);
  } else {
    vol = std::move(eval::make_synthetic_scene(scene.synthetic.kind).volume);
  }
  m.volume_path = vol.path;
  m.dims = vol.grid.dims;
  m.spacing_m = vol.grid.spacing_m;
  m.orientation = vol.orientation();
  m.direction = vol.direction;
  m.nan_voxels = vol.nan_voxels;
  m.inf_voxels = vol.inf_voxels;
  const bool any_finite = vol.finite_voxels > 0;
  log << "         " << vol.grid.dims[0] << " x " << vol.grid.dims[1] << " x " << vol.grid.dims[2]
      << " voxels, spacing " << fmt(vol.grid.spacing_m.x * 1e3) << " x " << fmt(vol.grid.spacing_m.y * 1e3)
      << " x " << fmt(vol.grid.spacing_m.z * 1e3) << " mm, " << vol.component_type << " via " << vol.reader
      << ", " << value_range_text(vol, m) << "\n"
      << "         orientation " << m.orientation << " (direction " << direction_text(vol.direction)
      << "); points below and in trace.csv are physical (ITK's LPS frame, origin + D (spacing * index))\n";
  if (!any_finite)
    throw std::runtime_error(scene.file + ": volume " + vol.path + " has no finite voxels (" +
                             std::to_string(m.nan_voxels) + " NaN, " + std::to_string(m.inf_voxels) +
                             " Inf): there is no isosurface");
  if (!(scene.hri.tau > vol.min_value && scene.hri.tau < vol.max_value))
    throw std::runtime_error(scene.file + ": field 'isovalue': " + fmt(scene.hri.tau) +
                             " is outside the finite data range [" + fmt(vol.min_value) + ", " +
                             fmt(vol.max_value) + "] of " + vol.path + ": there is no isosurface");

  // 2. Engine: the scene's passes on the GPU (dense or sparse), the CPU reference beside it.
  engine::ContextOptions co;
  co.device = opt.device;
  auto ctx = engine::VulkanContext::create(co);
  if (!ctx) throw std::runtime_error("Vulkan: " + ctx.error);
  s.vk = std::move(*ctx.value);
  engine::VulkanContext& vk = *s.vk;
  m.gpu_device = vk.info().name;
  m.gpu_device_type = vk.info().type;
  log << "device   " << m.gpu_device << " (" << m.gpu_device_type << ", " << vk.info().driver << ")\n";
  const EngineRun er = run_engine(scene, vol, vk, opt, m, log);
  s.first = er.published;
  // What the surface error is measured against, and the script is cast on: the dense fp32
  // samples of the same passes (CPU reference). For a dense or bricked fp32 snapshot its
  // isosurface is the published one (the bricks hold the same samples wherever a cell
  // can straddle tau); for compact samples it is the surface before rounding.
  s.truth = er.truth;
  s.live.passes = scene_passes(scene);
  s.live.iso = core::Isosurface{scene.hri.tau, scene.hri.inside};
  s.live.background = float(s.live.iso.outside_value(vol.min_value, vol.max_value));  // as run_engine
  s.live.format = scene_sample_format(scene);

  // 3. Script, servo parameters, workspace.
  s.hri = scene.hri;
  s.script = sim::make_touch_script(*s.truth, s.hri, scene.script);
  s.world_T_device.scale = scene.workspace_scale;
  s.world_T_device.translation_m = vol.grid.centre_m();

  // 4. Edits: the brushes (GPU), the undo history and the live field over a copy of the volume.
  if (scene.edits.present) {
    check_scene_brushes(scene, vol);
    s.session = std::make_unique<EditSession>(engine::Volume(vol), &vk, s.live, scene.edits.history_limit_mib);
    s.first = s.session->current();
    log << "edits    " << scene.edits.timeline.size() << " timeline entries, " << scene.edits.button_down.size()
        << " button press(es), brushes on the " << (s.session->sculptor().on_gpu() ? "GPU" : "CPU")
        << ", undo limit " << fmt(scene.edits.history_limit_mib) << " MiB; first snapshot version "
        << s.first->version << " (LiveField, " << s.live.passes.size() << " pass(es))\n";
  }
  const Vec3 contact_phys = vol.to_physical(s.script.contact_point_m);
  const Vec3 normal_phys = vol.direction_apply(s.script.contact_normal);
  log << "script   contact at (" << fmt(contact_phys.x * 1e3, 4) << ", " << fmt(contact_phys.y * 1e3, 4) << ", "
      << fmt(contact_phys.z * 1e3, 4) << ") mm (physical, LPS), normal (" << fmt(normal_phys.x, 3) << ", "
      << fmt(normal_phys.y, 3) << ", " << fmt(normal_phys.z, 3) << "), " << fmt(s.script.duration_s, 3) << " s at "
      << fmt(s.hri.rate_hz) << " Hz\n";
  return s;
}

namespace {
// The servo simulation's progress line (a bar on a terminal, a line per quarter in a log),
// and the stop check between ticks.
std::function<void(long, long)> servo_progress(const RunOptions& opt) {
  const bool tty = opt.progress && ::isatty(STDERR_FILENO);
  auto last_quarter = std::make_shared<int>(-1);
  return [tty, last_quarter, show = opt.progress](long k, long total) {
    throw_if_stop_requested("servo simulation, tick " + std::to_string(k) + " of " + std::to_string(total));
    if (!show) return;
    const int pct = int(100 * k / total);
    if (tty) {
      std::cerr << "\rservo    [" << std::string(std::size_t(pct / 4), '#')
                << std::string(std::size_t(25 - pct / 4), '.') << "] " << std::setw(3) << pct << "%  "
                << k << "/" << total << " ticks" << (k == total ? "\n" : "") << std::flush;
    } else if (pct / 25 != *last_quarter) {  // not a terminal: a line per quarter
      *last_quarter = pct / 25;
      std::cerr << "servo    " << k << "/" << total << " ticks (" << pct << "%)\n";
    }
  };
}

// The scene in the live session's simulated mode: the servo, the edits and the recorder
// clocked in simulated time on this thread (what the app and `run --live` run on threads).
std::vector<sim::TraceRow> simulate(const Scene& scene, SceneSetup& setup, const RunOptions& opt,
                                    servo::TripleBuffer<core::SampleField>& published, std::optional<EditDriver>& edits) {
  const servo::HriParams& hp = setup.hri;
  const servo::WorkspaceTransform& xf = setup.world_T_device;
  const sim::TouchScript& script = setup.script;
  Vec3 start_w, v0;
  script.at(0.0, start_w, v0);
  sim::SimDevice device(scene.device, xf.to_device(start_w));
  servo::HriRenderer renderer(hp);
  session::LiveSessionConfig lc;
  lc.servo.rate_hz = hp.rate_hz;
  lc.servo.world_T_device = xf;
  if (edits) {
    lc.drill = edits->drill();
    lc.on_applied = [&edits](const EditEvent& e, const EditOutcome& o, session::EditSource src) { edits->on_applied(e, o, src); };
  }
  if (!opt.record_path.empty()) {
    lc.record_path = opt.record_path;
    lc.record_header = recording_header(scene, setup);
  }
  session::LiveSession live(setup.session.get(), published, renderer, std::move(lc));
  session::SimulatedRun sr;
  sr.device = &device;
  sr.script = &script;
  sr.world_T_device = xf;
  if (edits) {
    sr.button_down = scene.edits.button_down;
    sr.after_tick = [&edits, &live](long k, sim::TraceRow& row) { (*edits)(live, k, row); };
  }
  sr.progress = servo_progress(opt);
  std::vector<sim::TraceRow> trace = live.run_simulated(sr);
  live.stop();  // the recording: end record, fsync, rename
  return trace;
}

// The trace's figures into `m`: tick times, contact forces and their steps, the stroke and
// lift-off, and the VHIP's surface error (against the edited volume a tick read, with edits).
// Returns how many contact ticks found a surface (true distance; unfiltered data).
std::pair<long, long> trace_figures(const std::vector<sim::TraceRow>& trace, const SceneSetup& setup,
                                    const EditDriver* edits, RunMetrics& m) {
  const servo::HriParams& hp = setup.hri;
  const sim::TouchScript& script = setup.script;
  const core::SampleField& truth = *setup.truth;
  const engine::Volume& vol = setup.volume;
  m.ticks = long(trace.size());
  std::vector<std::int64_t> ns;
  ns.reserve(trace.size());
  double sum_ns = 0, err2 = 0, fo2 = 0, fsum = 0, dir2 = 0, raw2 = 0;
  long found = 0, dir_pairs = 0, raw_found = 0;
  // With filters: the unfiltered data's isosurface, to see how far smoothing moved the surface.
  std::optional<core::SampleField> unfiltered;
  for (const auto& p : m.passes)
    if (p.kind == engine::PassKind::Gaussian || p.kind == engine::PassKind::Closing) m.has_unfiltered = true;
  if (m.has_unfiltered) {
    unfiltered = engine::run_chain_cpu(vol, {engine::PassDesc::gradient()}).samples;
    unfiltered->background = truth.background;
  }
  // One contact tick's surface error (true distance, first-order estimate) into the figures.
  const auto add_error = [&](const SurfaceDistance& d, double fo) {
    m.surface_search_radius_m = std::max(m.surface_search_radius_m, d.searched_radius_m);
    if (d.found) {
      ++found;
      err2 += d.distance_m * d.distance_m;
      m.surface_err_max_m = std::max(m.surface_err_max_m, d.distance_m);
    } else {
      ++m.surface_err_not_found_ticks;
    }
    fo2 += fo * fo;
    m.first_order_err_max_m = std::max(m.first_order_err_max_m, fo);
  };
  const sim::TraceRow* prev = nullptr;
  for (const auto& r : trace) {
    ns.push_back(r.tick_ns);
    sum_ns += double(r.tick_ns);
    m.plane_updates += r.plane_update;
    m.saturated_ticks += r.saturated;
    m.fault_ticks += r.fault;
    const sim::TraceRow* last = prev;
    prev = &r;
    const bool stroking = r.t_s >= script.t_stroke && r.t_s < script.t_lift;
    m.stroke_ticks += stroking;
    m.stroke_contact_ticks += stroking && r.contact;
    if (r.t_s >= script.t_lift && r.contact) {
      ++m.lift_contact_ticks;
      m.lift_max_force_n = std::max(m.lift_max_force_n, core::norm(r.force_n));
      const double outward = core::dot(r.force_n, script.contact_normal);
      if (outward < 0) {
        ++m.lift_inward_ticks;
        m.lift_max_inward_force_n = std::max(m.lift_max_inward_force_n, -outward);
      }
    }
    if (!r.contact) continue;
    ++m.contact_ticks;
    const double f = core::norm(r.force_n);
    if (last && last->contact) {
      const double step = std::abs(f - core::norm(last->force_n));
      if (step > m.max_force_step_n) {
        m.max_force_step_n = step;
        m.max_force_step_t_s = r.t_s;
      }
      const double vstep = core::norm(r.force_n - last->force_n);
      if (vstep > m.max_force_vector_step_n) {
        m.max_force_vector_step_n = vstep;
        m.max_force_vector_step_t_s = r.t_s;
      }
    }
    fsum += f;
    if (last && last->contact && f > 0 && core::norm(last->force_n) > 0) {
      const double c = std::clamp(core::dot(r.force_n, last->force_n) / (f * core::norm(last->force_n)), -1.0, 1.0);
      const double a = std::acos(c) * 180.0 / M_PI;
      dir2 += a * a;
      ++dir_pairs;
      if (a > m.force_dir_step_max_deg) {
        m.force_dir_step_max_deg = a;
        m.force_dir_step_max_t_s = r.t_s;
      }
    }
    if (edits && r.version > 1) {  // the surface moved: measured against the edited volume the tick read
      ++m.edits.contact_ticks_after_edit;
      m.max_force_n = std::max(m.max_force_n, f);
      m.max_penetration_m = std::max(m.max_penetration_m, r.penetration_m);
      const auto it = edits->edited_distance.find(long(&r - trace.data()));
      if (it != edits->edited_distance.end()) add_error(it->second.d, it->second.first_order_m);
      continue;
    }
    if (unfiltered) {
      const SurfaceDistance du = distance_to_isosurface(*unfiltered, hp.tau, r.vhip_m);
      if (du.found) {
        ++raw_found;
        raw2 += du.distance_m * du.distance_m;
        m.unfiltered_err_max_m = std::max(m.unfiltered_err_max_m, du.distance_m);
      }
    }
    m.max_force_n = std::max(m.max_force_n, f);
    m.max_penetration_m = std::max(m.max_penetration_m, r.penetration_m);
    // True distance of the VHIP from the isosurface of the trilinear field (bounded search).
    add_error(distance_to_isosurface(truth, hp.tau, r.vhip_m), first_order_distance(truth, hp.tau, r.vhip_m));
  }
  // Steps of |F| that the contact-only figure cannot see: a drop to zero from contact (every
  // release, inside the object or not), and any step between two consecutive ticks.
  {
    for (std::size_t i = 1; i < trace.size(); ++i) {
      const double f0 = core::norm(trace[i - 1].force_n), f1 = core::norm(trace[i].force_n);
      if (std::abs(f1 - f0) > m.max_any_step_n) {
        m.max_any_step_n = std::abs(f1 - f0);
        m.max_any_step_t_s = trace[i].t_s;
      }
      if (trace[i - 1].contact && !trace[i].contact && f0 > m.max_release_step_n) {
        m.max_release_step_n = f0;
        m.max_release_step_t_s = trace[i].t_s;
      }
    }
  }
  const std::vector<double> ns_d(ns.begin(), ns.end());
  m.tick_ns_median = ns.empty() ? 0 : percentile(ns_d, 0.5);
  m.tick_ns_p99 = ns.empty() ? 0 : percentile(ns_d, 0.99);
  m.tick_ns_max = ns.empty() ? 0 : double(*std::max_element(ns.begin(), ns.end()));
  m.tick_ns_mean = ns.empty() ? 0 : sum_ns / double(ns.size());
  if (m.contact_ticks) {
    m.mean_contact_force_n = fsum / double(m.contact_ticks);
    m.first_order_err_rms_m = std::sqrt(fo2 / double(m.contact_ticks));
  }
  if (found) m.surface_err_rms_m = std::sqrt(err2 / double(found));
  if (dir_pairs) m.force_dir_step_rms_deg = std::sqrt(dir2 / double(dir_pairs));
  if (raw_found) m.unfiltered_err_rms_m = std::sqrt(raw2 / double(raw_found));

  return {found, raw_found};
}

// The run's summary.json ("status": "complete": written last, once every other output is whole).
nlohmann::ordered_json summary_json(const Scene& scene, const SceneSetup& setup, const RunMetrics& m, long found,
                                    long raw_found, bool with_edits) {
  const engine::Volume& vol = setup.volume;
  const servo::HriParams& hp = setup.hri;
  const sim::TouchScript& script = setup.script;
  const bool any_finite = vol.finite_voxels > 0;
  const bool paper = hp.variant == servo::Variant::kPaper;
  const Vec3 contact_phys = vol.to_physical(script.contact_point_m);
  const Vec3 normal_phys = vol.direction_apply(script.contact_normal);
  nlohmann::ordered_json j;
  j["status"] = "complete";
  j["scene"] = {{"file", scene.file}, {"name", scene.name}};
  j["volume"] = {{"path", m.volume_path},
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
  j["servo"] = {{"algorithm", paper ? "HRI, the paper's Figure 2 as printed" : "HRI, robust variant (Figure 2 plus the departures in servo/hri.h)"},
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
  j["contact"] = {{"ticks", m.contact_ticks},
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
                  {"stiffness_bound_n_per_m", m.k_bound_n_per_m},
                  {"stiffness_above_bound", m.k_above_bound},
                  {"fault_ticks", m.fault_ticks}};
  // No contact tick (or no surface found): there is no error to report, not an error of 0.
  const auto or_null = [](bool have, double v) { return have ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); };
  j["error"] = {{"surface_distance_m", {{"rms", or_null(found > 0, m.surface_err_rms_m)}, {"max", or_null(found > 0, m.surface_err_max_m)},
                                        {"ticks_without_surface_within_radius", m.surface_err_not_found_ticks},
                                        {"search_radius_m", m.surface_search_radius_m},
                                        {"measured_on", "the dense fp32 samples of the scene's passes (CPU reference): "
                                                        "the published isosurface for dense and bricked fp32, the surface "
                                                        "before rounding for compact samples; a tick that read an edited "
                                                        "snapshot against the edited volume it read"},
                                        {"method", "true distance from the VHIP to the isosurface of the trilinear field "
                                                   "(branch and bound over cells, error below min(1e-3 voxel, max(1e-6 voxel, 1 % of the distance)))"}}},
                {"surface_distance_to_unfiltered_m",
                 {{"rms", or_null(m.has_unfiltered && raw_found > 0, m.unfiltered_err_rms_m)},
                  {"max", or_null(m.has_unfiltered && raw_found > 0, m.unfiltered_err_max_m)},
                  {"method", "with filters in the pass list: true distance from the VHIP to the isosurface of the "
                             "unfiltered data (gradient only); null without filters"}}},
                {"first_order_estimate_m", {{"rms", or_null(m.contact_ticks > 0, m.first_order_err_rms_m)},
                                            {"max", or_null(m.contact_ticks > 0, m.first_order_err_max_m)},
                                            {"method", "|f(VHIP) - tau| / |grad f(VHIP)|: not a distance, unbounded "
                                                       "where the field is flat; shown for comparison only"}}}};
  j["script"] = {{"contact_point_m", {contact_phys.x, contact_phys.y, contact_phys.z}},
                 {"contact_normal", {normal_phys.x, normal_phys.y, normal_phys.z}},
                 {"duration_s", script.duration_s},
                 {"phases_s", {{"press", script.t_press}, {"stroke", script.t_stroke}, {"lift", script.t_lift}}},
                 {"stroke_ticks", m.stroke_ticks},
                 {"stroke_contact_ticks", m.stroke_contact_ticks},
                 {"stroke_contact_fraction", m.stroke_ticks ? nlohmann::ordered_json(double(m.stroke_contact_ticks) / double(m.stroke_ticks))
                                                            : nlohmann::ordered_json(nullptr)},
                 {"lift_contact_ticks", m.lift_contact_ticks},
                 {"lift_max_force_n", m.lift_max_force_n},
                 {"lift_inward_ticks", m.lift_inward_ticks},
                 {"lift_max_inward_force_n", m.lift_max_inward_force_n}};
  j["picture"] = {{"file", m.picture_drawn ? nlohmann::ordered_json("surface.png") : nlohmann::ordered_json(nullptr)},
                  {"note", m.picture_note}};
  j["plots"] = m.plots_drawn ? nlohmann::ordered_json::array({"force_depth.png", "tick_time.png"})
                             : nlohmann::ordered_json::array();
  if (with_edits) j["edits"] = edits_json(m.edits, scene);
  return j;
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
  md << "| | |\n|---|---|\n"
     << "| volume | `" << m.volume_path << "` (" << m.dims[0] << " x " << m.dims[1] << " x " << m.dims[2]
     << ", spacing " << fmt(m.spacing_m.x * 1e3) << " x " << fmt(m.spacing_m.y * 1e3) << " x "
     << fmt(m.spacing_m.z * 1e3) << " mm, " << vol.component_type << "; " << value_range_text(vol, m) << ") |\n"
     << "| orientation | " << m.orientation << ", direction " << direction_text(m.direction)
     << "; reported points and forces are physical (ITK's LPS frame: origin + D (spacing * index)) |\n"
     << "| isovalue | " << fmt(hp.tau) << " (inside: value " << (hp.inside == core::InsideIs::kAbove ? ">" : "<")
     << " isovalue) |\n"
     << "| Vulkan device | " << m.gpu_device << " (" << m.gpu_device_type << ") |\n"
     << "| engine | " << m.engine_mode << " mode, " << m.sample_format << " samples, passes "
     << pass_list_text(m.passes) << "; snapshot " << m.snapshot_bytes << " B ("
     << fmt(100.0 * double(m.snapshot_bytes) / double(std::max<std::uint64_t>(1, m.dense_fp32_bytes)), 3)
     << " % of the dense fp32 " << m.dense_fp32_bytes << " B)"
     << (m.bricks_total ? ", " + std::to_string(m.bricks_active) + " of " + std::to_string(m.bricks_total) + " bricks active"
                        : std::string())
     << (m.engine_fallback.empty() ? std::string() : "; **sparse GPU chain not used: " + m.engine_fallback + "**")
     << " (details below) |\n"
     << (m.engine_mode == "sparse" ? "| GPU stages (sum) | " : "| gradient pass | ") << "GPU " << fmt(m.gpu_gradient_ms, 4) << " ms ("
     << (m.gpu_timestamps ? "GPU timestamps" : "wall clock") << ", " << m.gpu_slabs << " slab(s)); CPU reference "
     << fmt(m.cpu_gradient_ms, 4) << " ms (one thread) |\n"
     << "| GPU vs CPU gradient | max abs " << fmt(m.max_abs_diff, 3)
     << "; relative (to the largest gradient magnitude) " << fmt(m.max_rel_diff, 3) << " |\n"
     << "| servo | K = " << fmt(hp.stiffness_n_per_m) << " N/m, B = " << fmt(hp.damping_n_s_per_m)
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
                        : std::string("no stroke in the script")) << " |\n"
     << "| lift-off | " << m.lift_contact_ticks << " contact ticks while the hand pulls the probe out, largest |F| "
     << fmt(m.lift_max_force_n, 4) << " N; " << m.lift_inward_ticks
     << " of them pull the probe into the object (largest inward component " << fmt(m.lift_max_inward_force_n, 4)
     << " N) |\n"
     << "| stiffness bound | K = " << fmt(hp.stiffness_n_per_m, 4) << " N/m, Colgate-Schenkel K_max = 2 (b - |B|) / T = "
     << fmt(m.k_bound_n_per_m, 4) << " N/m" << (m.k_above_bound ? " (ABOVE the bound: the contact may buzz)" : "")
     << " |\n"
     << "| contact | max force " << fmt(m.max_force_n, 4) << " N, mean " << fmt(m.mean_contact_force_n, 4)
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
     << "| largest force direction step | " << fmt(m.force_dir_step_max_deg, 3) << " deg at t = "
     << fmt(m.force_dir_step_max_t_s, 5) << " s (RMS " << fmt(m.force_dir_step_rms_deg, 3)
     << " deg; angle between the forces of consecutive contact ticks) |\n"
     << (m.has_unfiltered && raw_found > 0
             ? "| distance from the unfiltered data's surface | RMS " + fmt(m.unfiltered_err_rms_m * 1e3, 4) + " mm, max " +
                   fmt(m.unfiltered_err_max_m * 1e3, 4) + " mm (how far the filters moved the felt surface) |\n"
             : std::string())
     << "| surface error of the VHIP | "
     << (found == 0 ? std::string(m.contact_ticks == 0 ? "not known: no contact tick" : "not known: no surface found")
                    : "true distance to the trilinear isosurface: RMS " + fmt(m.surface_err_rms_m * 1e3, 4) + " mm, max " +
                          fmt(m.surface_err_max_m * 1e3, 4) + " mm (" +
                          fmt(m.surface_err_rms_m / std::min({m.spacing_m.x, m.spacing_m.y, m.spacing_m.z}), 3) +
                          " voxel RMS)")
     << (m.surface_err_not_found_ticks
                               ? "; " + std::to_string(m.surface_err_not_found_ticks) +
                                     " contact ticks with no surface within " + fmt(m.surface_search_radius_m * 1e3, 4) +
                                     " mm (left out of RMS and max)"
                               : std::string())
     << " |\n\n";
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
     << " ticks, the VHIP stayed within " << fmt(m.surface_err_max_m * 1e3, 4)
     << " mm of the trilinear isosurface (RMS " << fmt(m.surface_err_rms_m * 1e3, 4) << " mm) on the "
     << m.contact_ticks - m.surface_err_not_found_ticks << " contact ticks where a surface was found. "
     << "The first-order estimate |f - tau| / |grad f| would have said RMS " << fmt(m.first_order_err_rms_m * 1e3, 4)
     << " mm, max " << fmt(m.first_order_err_max_m * 1e3, 4) << " mm.\n\n";
  if (with_edits) md << edits_markdown(m.edits, scene);
  md << engine_markdown(m);
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

RunMetrics run_scene_steps(const Scene& scene, const RunOptions& opt, std::ostream& log) {
  throw_if_stop_requested("start");
  SceneSetup setup = setup_scene(scene, opt, log);
  throw_if_stop_requested("engine set-up (samples computed, servo not started)");
  RunMetrics& m = setup.metrics;
  const engine::Volume& vol = setup.volume;
  const std::shared_ptr<const core::SampleField> field = setup.first;
  const servo::HriParams& hp = setup.hri;
  const sim::TouchScript& script = setup.script;
  // Colgate and Schenkel's passivity bound for the scene's K, B and rate, with the damping
  // at the handle b = device + hand damping [N s/m]: a stiffer wall may buzz (K = 1e6 N/m
  // on the sphere at 1 kHz: 152 on/off flips). Warned in the log and reported.
  m.k_bound_n_per_m = sim::colgate_k_max(scene.device.damping_n_s_per_m + scene.device.hand_damping_n_s_per_m,
                                           hp.damping_n_s_per_m, 1.0 / hp.rate_hz);
  m.k_above_bound = !(hp.stiffness_n_per_m <= m.k_bound_n_per_m);
  if (m.k_above_bound)
    log << "warning: stiffness " << hp.stiffness_n_per_m << " N/m is above the Colgate-Schenkel bound K_max = "
        << "2 (b - |B|) / T = " << m.k_bound_n_per_m << " N/m (b = device + hand damping, B = servo damping, "
        << "T = 1 / rate_hz): the contact may buzz; lower K or B, or raise the rate\n";

  // Publish the samples: the servo reads them through the one publication point.
  servo::TripleBuffer<core::SampleField> published;
  published.publish(field);
  std::optional<EditDriver> edits;
  if (setup.session) edits.emplace(scene, setup);
  const std::vector<sim::TraceRow> trace = simulate(scene, setup, opt, published, edits);
  const auto [found, raw_found] = trace_figures(trace, setup, edits ? &*edits : nullptr, m);
  if (m.contact_ticks == 0)
    log << "no contact: the probe never touched the isosurface in " << m.ticks
        << " ticks; the surface error is not known (null in summary.json)\n";
  log << "steps    |F| between contact ticks " << fmt(m.max_force_step_n, 4) << " N, F vector "
      << fmt(m.max_force_vector_step_n, 4) << " N (t = " << fmt(m.max_force_vector_step_t_s, 5) << " s), release "
      << fmt(m.max_release_step_n, 4) << " N (t = " << fmt(m.max_release_step_t_s, 5) << " s), any ticks "
      << fmt(m.max_any_step_n, 4) << " N (t = " << fmt(m.max_any_step_t_s, 5) << " s)\n";

  // 6. Outputs, each written whole or not at all (RunFolder has made and locked the folder).
  const std::string dir = opt.out_dir;
  throw_if_stop_requested("outputs (servo finished, no file written yet)");
  if (scene.write_trace) write_file_atomic((fs::path(dir) / "trace.csv").string(), trace_csv(trace, vol));
  if (scene.write_trace && scene.draw_plots) m.plots_drawn = draw_plots(scene, dir, script, m.plot_note);
  else m.plot_note = "plots turned off in the scene (outputs.plots / outputs.trace_csv)";
  throw_if_stop_requested("outputs (trace and plots written)");
  if (scene.draw_plots) {
    // The run's picture (ray-cast on the same Vulkan device); never throws.
    // With edits the path is thinned (thin_path): the same picture serves as before.png.
    const RunPicture pic = render_run_picture(scene, vol, *field, edits ? thin_path(trace) : trace,
                                              (fs::path(dir) / "surface.png").string(),
                                              setup.vk.get(), opt.device);
    m.picture_drawn = pic.error.empty();
    m.picture_note = m.picture_drawn ? pic.caption : pic.error;
    if (!m.picture_drawn) log << "picture  not drawn: " << pic.error << "\n";
  }
  throw_if_stop_requested("outputs (trace, plots and picture written)");
  if (edits) finish_edits(scene, setup, *edits, trace, dir, m, log);
  throw_if_stop_requested("outputs (all but summary.json and report.md written)");

  const std::string summary_text = summary_json(scene, setup, m, found, raw_found, edits.has_value()).dump(2) + "\n";
  write_file_atomic((fs::path(dir) / "report.md").string(), report_markdown(scene, setup, m, found, raw_found, edits.has_value()));
  // Last: "complete" only once every other output is whole.
  write_file_atomic((fs::path(dir) / "summary.json").string(), summary_text);
  return m;
}
}  // namespace

RunMetrics run_scene(const Scene& scene, const RunOptions& opt, std::ostream& log) {
  RunFolder folder(opt.out_dir, scene.file, scene.name);
  try {
    return run_scene_steps(scene, opt, log);
  } catch (const Interrupted& e) {
    if (folder.mark_interrupted(e.stage, e.signal))
      log << "\ninterrupted (" << (e.signal == SIGTERM ? "SIGTERM" : "SIGINT") << ") during " << e.stage
          << ": " << (fs::path(opt.out_dir) / "summary.json").string() << " says \"status\": \"interrupted\"\n";
    throw;
  } catch (const std::exception& e) {
    folder.mark_failed(e.what());
    throw;
  }
}

}  // namespace isotouch::app
