#include "isotouch/run/engine_run.h"
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
#include "isotouch/core/brick_field.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/core/field_view.h"
#include "isotouch/run/names.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/sparse_chain.h"
#include "isotouch/run/text.h"

namespace isotouch::run {
namespace fs = std::filesystem;
namespace {

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

// The dense chain on `vk` (PassChain, one command buffer) or, without one, on the CPU backend.
engine::ChainOutput dense_engine(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                                 engine::VulkanContext* vk, const RunOptions& opt, RunMetrics& m) {
  if (!vk) {
    const unsigned threads = engine::hardware_threads();
    m.engine_describe = "run_chain_cpu on " + std::to_string(threads) + " thread(s)";
    m.engine_ran = "run_chain_cpu (CPU backend, " + std::to_string(threads) + " thread(s), dense)";
    return engine::run_chain_cpu(vol, passes, threads);
  }
  auto chain = engine::PassChain::create(*vk, passes);
  if (!chain) throw std::runtime_error(vol.path + ": " + chain.error);
  engine::ChainOutput out = (*chain.value)->run(vol, opt.max_binding_bytes);
  m.engine_describe = (*chain.value)->describe();
  m.engine_ran = "PassChain (GPU, dense, one command buffer)";
  return out;
}

// Dense: the dense chain (GPU or CPU backend), run_chain_cpu as the reference.
EngineRun run_dense(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                    engine::VulkanContext* vk, const RunOptions& opt, float background, RunMetrics& m) {
  engine::ChainOutput out = dense_engine(vol, passes, vk, opt, m);
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

// The sparse GPU chain's snapshot and figures into m.
std::shared_ptr<core::SampleField> sparse_gpu_field(engine::SparseOutput& gpu, RunMetrics& m) {
  auto field = std::make_shared<core::SampleField>(std::move(gpu.field));
  m.gpu_passes = figures(gpu.passes);
  m.gpu_upload_ms = gpu.upload_ms;
  m.gpu_download_ms = gpu.download_ms;
  m.gpu_submit_wall_ms = gpu.submit_wall_ms;
  m.publish_ms = gpu.publish_ms;
  // GPU stages only (labels "... (GPU)"): the host stages are wall time, reported apart.
  m.gpu_gradient_ms = 0;
  bool any_gpu = false, all_stamped = true;
  for (const auto& p : gpu.passes) {
    if (p.label.size() < 5 || p.label.compare(p.label.size() - 5, 5, "(GPU)") != 0) continue;
    any_gpu = true;
    all_stamped = all_stamped && p.ms >= 0;
    m.gpu_gradient_ms += std::max(0.0, p.ms);
  }
  m.gpu_timestamps = any_gpu && all_stamped;
  if (!m.gpu_timestamps) m.gpu_gradient_ms = gpu.submit_wall_ms;
  m.gpu_slabs = int(gpu.stats.slabs);
  m.bricks_total = gpu.stats.bricks_total;
  m.bricks_candidates = gpu.stats.candidates;
  m.bricks_active = gpu.stats.active;
  m.snapshot_bytes = core::snapshot_bytes(*field);
  return field;
}

// Where the sparse GPU chain cannot run the scene: the dense chain's samples converted to
// bricks, its figures into m (m.engine_fallback says why).
std::shared_ptr<core::SampleField> dense_stand_in(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                                                  engine::VulkanContext* vk, const RunOptions& opt,
                                                  const core::Isosurface& iso, float background,
                                                  core::SampleFormat format, RunMetrics& m) {
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
  auto field = to_bricks(*d.published, iso, format, m);
  m.publish_ms = ms_since(t0);
  m.engine_ran = (vk ? "PassChain (GPU, dense) + " : "run_chain_cpu (CPU backend, dense) + ") + m.engine_ran;
  return field;
}

// The sparse chain on `vk` (SparseChain) or, without one, on the CPU backend; nullopt where it
// cannot run the scene (m.engine_fallback says why).
std::optional<engine::SparseOutput> sparse_engine(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                                                  engine::VulkanContext* vk, const RunOptions& opt,
                                                  const core::Isosurface& iso, float background,
                                                  core::SampleFormat format, RunMetrics& m) {
  try {
    if (!vk) {
      const unsigned threads = engine::hardware_threads();
      m.engine_describe = "run_sparse_cpu on " + std::to_string(threads) + " thread(s)";
      m.engine_ran = "run_sparse_cpu (CPU backend, " + std::to_string(threads) + " thread(s), candidate bricks only)";
      return engine::run_sparse_cpu(vol, passes, iso, background, format, false, threads);
    }
    auto chain = engine::SparseChain::create(*vk, passes);
    if (!chain) throw std::runtime_error(vol.path + ": " + chain.error);
    m.engine_describe = (*chain.value)->describe();
    auto out = (*chain.value)->run(vol, iso, background, format, opt.max_binding_bytes);
    m.engine_ran = "SparseChain (GPU, candidate bricks only)";
    return out;
  } catch (const engine::VolumeError& e) {
    // Not implemented yet, or a pass list the sparse chain cannot hold (e.g. a wide
    // Gaussian): the dense chain stands in, and the report says why.
    m.engine_fallback = e.what();
    return std::nullopt;
  }
}

// Sparse: the sparse chain (GPU or CPU backend), run_sparse_cpu as the reference; where the
// chain cannot run the scene, the dense chain plus a conversion of its samples to bricks
// stands in (and the report says so).
EngineRun run_sparse(const engine::Volume& vol, const std::vector<engine::PassDesc>& passes,
                     engine::VulkanContext* vk, const RunOptions& opt, const core::Isosurface& iso,
                     float background, core::SampleFormat format, RunMetrics& m) {
  // The dense fp32 samples of the same passes: what the errors are measured against.
  const auto t_truth = std::chrono::steady_clock::now();
  engine::ChainOutput dense_ref = engine::run_chain_cpu(vol, passes);
  const double truth_ms = ms_since(t_truth);
  auto truth = std::make_shared<core::SampleField>(std::move(*dense_ref.samples));
  truth->background = background;
  truth->version = 1;
  m.dense_fp32_bytes = vol.grid.voxel_count() * sizeof(core::Sample);

  std::optional<engine::SparseOutput> gpu = sparse_engine(vol, passes, vk, opt, iso, background, format, m);
  std::shared_ptr<core::SampleField> field = gpu ? sparse_gpu_field(*gpu, m)
                                                 : dense_stand_in(vol, passes, vk, opt, iso, background, format, m);
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

}  // namespace

EngineRun run_engine(const Scene& scene, const engine::Volume& vol, engine::VulkanContext* vk,
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
  if (!m.engine_fallback.empty()) log << "         (sparse chain not used: " << m.engine_fallback << ")\n";
  for (std::size_t i = 0; i < m.gpu_passes.size(); ++i)
    log << "         " << (vk ? "GPU " : "CPU backend ") << m.gpu_passes[i].label << " " << fmt(m.gpu_passes[i].ms, 4) << " ms ("
        << m.gpu_passes[i].dispatches << " dispatch(es))\n";
  for (const auto& p : m.cpu_passes) log << "         CPU " << p.label << " " << fmt(p.ms, 4) << " ms\n";
  if (m.bricks_total)
    log << "bricks   " << m.bricks_active << " active of " << m.bricks_total << " (" << m.bricks_candidates
        << " candidates computed); snapshot " << m.snapshot_bytes << " B against " << m.dense_fp32_bytes
        << " B dense fp32 (" << fmt(100.0 * double(m.snapshot_bytes) / double(std::max<std::uint64_t>(1, m.dense_fp32_bytes)), 3)
        << " %)\n";
  log << (vk ? "GPU vs CPU" : "CPU backend vs one-thread reference") << " max |difference| " << fmt(m.max_abs_diff, 3) << " (relative " << fmt(m.max_rel_diff, 3)
      << ")\n";
  return r;
}

}  // namespace isotouch::run
