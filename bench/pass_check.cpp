// pass_check.cpp - `isotouch check` and `check --all`. See pass_check.h.
#include "isotouch/bench/pass_check.h"
#include "isotouch/io/vdb_io.h"

#include <algorithm>
#include <iostream>
#include <chrono>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iomanip>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "isotouch/engine/cpu_filters.h"
#include "isotouch/engine/gradient_pass.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/passes.h"
#include "isotouch/io/scene.h"
#include "isotouch/eval/shapes.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/engine/ulp.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::bench {
using io::load_any_volume;
using io::load_scene;
using io::Scene;
namespace {

// One output of one pass, test (GPU or OpenVDB) against reference.
struct Row {
  std::string pass, output;
  std::size_t n = 0;
  double max_abs = 0, max_rel = 0;  // max |t - r|; relative to max |r| over finite r
  engine::UlpStats ulp;
  std::size_t nonfinite_test = 0, nonfinite_ref = 0;
  double test_ms = -1, ref_ms = -1;
  std::uint64_t bound = 0;          // allowed ULP max
  std::string bound_text;           // "bit-identical", "<= 64 ULP"
  bool ok = true;
};

Row compare(std::string pass, std::string output, const std::vector<float>& t, const std::vector<float>& r,
            std::uint64_t bound, std::string bound_text) {
  Row row;
  row.pass = std::move(pass);
  row.output = std::move(output);
  row.bound = bound;
  row.bound_text = std::move(bound_text);
  if (t.size() != r.size())
    throw std::logic_error("check --all: " + row.pass + " " + row.output + ": GPU gives " + std::to_string(t.size()) +
                           " values, CPU " + std::to_string(r.size()));
  row.n = t.size();
  row.ulp = engine::ulp_stats(t, r);
  double max_ref = 0;
  for (std::size_t i = 0; i < t.size(); ++i) {
    const bool ft = std::isfinite(t[i]), fr = std::isfinite(r[i]);
    row.nonfinite_test += !ft;
    row.nonfinite_ref += !fr;
    if (ft && fr) row.max_abs = std::max(row.max_abs, std::abs(double(t[i]) - double(r[i])));
    if (fr) max_ref = std::max(max_ref, std::abs(double(r[i])));
  }
  row.max_rel = max_ref > 0 ? row.max_abs / max_ref : row.max_abs;
  row.ok = row.ulp.max <= bound && row.nonfinite_test == 0 && row.nonfinite_ref == 0;
  return row;
}

std::vector<float> flatten(const core::SampleField& f) {
  std::vector<float> v;
  v.reserve(f.samples.size() * 4);
  for (const auto& s : f.samples) v.insert(v.end(), {s.value, s.gx, s.gy, s.gz});
  return v;
}

std::string ms_text(double ms) {
  if (ms < 0) return "n/a";
  std::ostringstream o;
  o << std::fixed << std::setprecision(ms < 10 ? 2 : 1) << ms;
  return o.str();
}

std::string sci(double v) {
  std::ostringstream o;
  o << std::setprecision(3) << v;
  return o.str();
}

engine::Volume load(const CheckAllOptions& opt, std::optional<double>& tau, std::string& where) {
  if (opt.scene_path.empty()) {
    where = opt.volume_path;
    return load_any_volume(opt.volume_path);
  }
  const Scene scene = load_scene(opt.scene_path);
  tau = scene.hri.tau;
  if (!scene.volume_path.empty()) {
    where = scene.volume_path + " (scene " + opt.scene_path + ")";
    return load_any_volume(scene.volume_path);
  }
  where = "synthetic " + scene.synthetic.kind + " (scene " + opt.scene_path + ")";
  if (scene.synthetic.kind == "sphere")
    return engine::make_sphere(scene.synthetic.dims, scene.synthetic.spacing_m, scene.synthetic.radius_vox);
  return std::move(eval::make_synthetic_scene(scene.synthetic.kind).volume);
}

bool env_validation() {
  const char* e = std::getenv("ISOTOUCH_VALIDATION");
  return e && std::string(e) == "1";
}

}  // namespace

int run_check_all(const CheckAllOptions& opt, std::ostream& out) {
  std::optional<double> tau;
  std::string where;
  engine::Volume vol = load(opt, tau, where);
  const bool validation = opt.validation || env_validation();

  engine::ContextOptions co;
  co.device = opt.device;
  co.validation = validation;
  co.synchronization_validation = validation;
  auto ctx_r = engine::VulkanContext::create(co);
  if (!ctx_r)
    throw std::runtime_error("Vulkan: " + ctx_r.error +
                             (validation ? " (validation needs VK_LAYER_KHRONOS_validation; Debian: "
                                           "vulkan-validationlayers)"
                                         : ""));
  engine::VulkanContext& ctx = **ctx_r.value;
  const bool cpu_device = ctx.info().type == "cpu";
  const std::uint64_t bound = cpu_device ? 0 : kUlpBoundOtherDevice;
  const std::string bound_text =
      cpu_device ? "bit-identical" : "<= " + std::to_string(kUlpBoundOtherDevice) + " ULP";
  const std::uint64_t max_binding = std::uint64_t(opt.max_binding_mib * 1024 * 1024);

  const std::vector<engine::PassDesc> passes = {engine::PassDesc::gaussian(1.0), engine::PassDesc::closing(1.0),
                                                engine::PassDesc::gradient(), engine::PassDesc::brick_minmax(1)};
  const auto& d = vol.grid.dims;
  out << std::setprecision(4) << "volume      " << where << " (" << d[0] << "x" << d[1] << "x" << d[2] << ", spacing "
      << vol.grid.spacing_m.x * 1e3 << " x " << vol.grid.spacing_m.y * 1e3 << " x " << vol.grid.spacing_m.z * 1e3
      << " mm)\n"
      << "values      ";
  if (vol.finite_voxels > 0)
    out << "[" << vol.min_value << ", " << vol.max_value << "]";
  else
    out << "no finite voxel";
  out << "; NaN voxels " << vol.nan_voxels << ", Inf voxels " << vol.inf_voxels << "\n";
  if (tau) out << "isovalue    " << *tau << " (from the scene)\n";
  out << "device      " << ctx.info().name << " (" << ctx.info().type << "); validation layer "
      << (validation ? "on (with synchronization validation; GPU times include its overhead)" : "off") << "\n"
      << "passes      ";
  for (std::size_t i = 0; i < passes.size(); ++i) out << (i ? ", " : "") << passes[i].label();
  out << (opt.scene_path.empty() ? " (default list)"
                                 : " (default list)")
      << "\n"
      << "rule        GPU vs CPU " << bound_text
      << (cpu_device ? " (a CPU device does the same float operations in the same order)"
                     : " (the driver may contract to FMA or reassociate)")
      << "; no NaN/Inf in any output; OpenVDB within " << kUlpBoundOpenVdb << " ULP (interior voxels)\n";
  if (max_binding) out << "bindings    at most " << opt.max_binding_mib << " MiB (z-slabs)\n";

  std::vector<Row> rows;
  std::size_t dispatches_total = 0;
  // Each pass on its own (its own GPU and CPU time), then the whole list as one chain.
  auto run_one = [&](const std::vector<engine::PassDesc>& list, const std::string& name) {
    auto chain = engine::PassChain::create(ctx, list);
    if (!chain) throw std::runtime_error("check --all: pass list " + name + ": " + chain.error);
    const engine::ChainOutput g = (*chain.value)->run(vol, max_binding);
    engine::ChainOutput c = engine::run_chain_cpu(vol, list);
    for (const auto& p : g.passes) dispatches_total += std::size_t(p.dispatches);
    if (opt.inject_mismatch && c.field && !c.field->empty() && list.front().kind == engine::PassKind::Gaussian) {
      float& v = c.field->front();  // 1000 ULP up: beyond the bound of any device
      for (int k = 0; k < 1000; ++k) v = std::nextafter(v, std::numeric_limits<float>::infinity());
    }
    double gms = 0, cms = 0;
    bool g_has = true;
    for (const auto& p : g.passes) {
      if (p.ms < 0) g_has = false;
      gms += p.ms;
    }
    for (const auto& p : c.passes) cms += p.ms;
    if (!g_has) gms = g.submit_wall_ms;  // no timestamps: submit to fence, wall clock
    auto add = [&](Row r) {
      r.test_ms = gms;
      r.ref_ms = cms;
      rows.push_back(std::move(r));
    };
    if (c.field) add(compare(name, "field", *g.field, *c.field, bound, bound_text));
    if (c.samples) add(compare(name, "value+gradient", flatten(*g.samples), flatten(*c.samples), bound, bound_text));
    if (c.bricks) {
      if (g.bricks->bricks != c.bricks->bricks) throw std::logic_error("check --all: brick counts differ");
      add(compare(name, "brick min", g.bricks->min, c.bricks->min, bound, bound_text));
      add(compare(name, "brick max", g.bricks->max, c.bricks->max, bound, bound_text));
      if (tau) {
        std::size_t active = 0;
        for (std::size_t i = 0; i < c.bricks->count(); ++i)
          active += c.bricks->min[i] <= *tau && *tau <= c.bricks->max[i];
        if (name == "chain")
          out << "bricks      " << active << " of " << c.bricks->count() << " 8^3 bricks straddle the isovalue "
              << *tau << " after the filters (" << std::setprecision(3)
              << 100.0 * double(active) / double(std::max<std::size_t>(1, c.bricks->count())) << " %)\n"
              << std::setprecision(4);
      }
    }
    return g;
  };
  for (const auto& p : passes) run_one({p}, p.label());

  // OpenVDB: the gradient of the unfiltered volume, interior voxels, against the CPU (and so
  // the GPU, which the gradient row holds bit for bit or within the bound).
  const OpenVdbGradient vdb = openvdb_gradient(vol);
  if (vdb.available) {
    const engine::ChainOutput cpu = engine::run_chain_cpu(vol, {engine::PassDesc::gradient()});
    std::vector<float> ours;
    ours.reserve(vdb.g.size());
    for (std::size_t i : vdb.voxel) {
      const auto& s = cpu.samples->samples[i];
      ours.insert(ours.end(), {s.gx, s.gy, s.gz});
    }
    Row r = compare("gradient", "vs OpenVDB " + vdb.version, ours, vdb.g, kUlpBoundOpenVdb,
                    "<= " + std::to_string(kUlpBoundOpenVdb) + " ULP");
    r.test_ms = cpu.passes.front().ms;
    r.ref_ms = vdb.ms;
    rows.push_back(std::move(r));
  }
  run_one(passes, "chain");

  // The table.
  out << "\n| pass | output | values | max abs | max rel | ULP max | ULP p99 | not identical | NaN/Inf GPU | "
         "NaN/Inf CPU | GPU ms | CPU ms | bound | verdict |\n"
         "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|\n";
  bool all_ok = true;
  for (const auto& r : rows) {
    all_ok = all_ok && r.ok;
    out << "| " << r.pass << " | " << r.output << " | " << r.n << " | " << sci(r.max_abs) << " | " << sci(r.max_rel)
        << " | " << r.ulp.max << " | " << r.ulp.p99 << " | " << r.ulp.differ << " | " << r.nonfinite_test << " | "
        << r.nonfinite_ref << " | " << ms_text(r.test_ms) << " | " << ms_text(r.ref_ms) << " | " << r.bound_text
        << " | " << (r.ok ? "ok" : "FAIL") << " |\n";
  }
  if (vdb.available)
    out << "(OpenVDB row: CPU gradient in the GPU ms column, OpenVDB copy + gradient in the CPU ms column)\n";
  else
    out << "OpenVDB     not built in (libopenvdb-dev missing): no independent gradient reference\n";
  out << "GPU ms: device timestamps of the passes (submit-to-fence wall time where the device has none); "
         "CPU ms: the one-thread reference, wall time; chain rows: the whole list in one command buffer, "
         "total time; "
      << dispatches_total << " dispatches in all\n";

  std::vector<std::string> why;
  for (const auto& r : rows)
    if (!r.ok) {
      std::ostringstream w;
      w << r.pass << " " << r.output << ": ";
      if (r.ulp.max > r.bound)
        w << r.ulp.differ << " values differ, ULP max " << r.ulp.max << " (bound " << r.bound_text
          << "), first at index " << r.ulp.first;
      if (r.nonfinite_test || r.nonfinite_ref)
        w << (r.ulp.max > r.bound ? ", " : "") << r.nonfinite_test << " NaN/Inf in the output, " << r.nonfinite_ref
          << " in the reference";
      why.push_back(w.str());
    }
  if (vol.nonfinite_voxels() > 0)
    why.push_back(std::to_string(vol.nonfinite_voxels()) + " non-finite voxels in the volume (NaN " +
                  std::to_string(vol.nan_voxels) + ", Inf " + std::to_string(vol.inf_voxels) + ")");
  if (validation && ctx.validation_messages() > 0)
    why.push_back(std::to_string(ctx.validation_messages()) + " validation messages (see stderr)");
  if (opt.inject_mismatch) out << "note        --inject-mismatch: the CPU Gaussian reference was altered on purpose\n";
  if (why.empty()) {
    out << "PASS        " << rows.size() << " comparisons"
        << (validation ? ", validation layer on, 0 messages" : "") << "\n";
    return 0;
  }
  out << "FAIL       ";
  for (const auto& w : why) out << " " << w << ";";
  out << "\n";
  return 3;
}

// ---- isotouch check VOLUME: the gradient pass against its CPU reference ------------------

namespace {

// Samples whose gradient is not finite: from non-finite voxels (NaN/Inf in the file),
// or overflow (finite voxels whose differences exceed float, e.g. values near 1e38).
struct GradientHealth {
  std::size_t nonfinite = 0;  ///< samples with a non-finite gradient component
  std::size_t overflow = 0;   ///< of those, samples whose 3x3x3 neighbourhood is all finite
  double max_norm = 0;        ///< largest finite |gradient| [value/m]
};
GradientHealth gradient_health(const engine::Volume& vol, const core::SampleField& f) {
  GradientHealth h;
  const auto& d = vol.grid.dims;
  for (int z = 0; z < d[2]; ++z)
    for (int y = 0; y < d[1]; ++y)
      for (int x = 0; x < d[0]; ++x) {
        const core::Sample& s = f.samples[vol.grid.index(x, y, z)];
        if (std::isfinite(s.gx) && std::isfinite(s.gy) && std::isfinite(s.gz)) {
          h.max_norm = std::max(h.max_norm, std::sqrt(double(s.gx) * s.gx + double(s.gy) * s.gy + double(s.gz) * s.gz));
          continue;
        }
        ++h.nonfinite;
        bool finite_input = true;
        for (int k = std::max(0, z - 1); k <= std::min(d[2] - 1, z + 1) && finite_input; ++k)
          for (int j = std::max(0, y - 1); j <= std::min(d[1] - 1, y + 1) && finite_input; ++j)
            for (int i = std::max(0, x - 1); i <= std::min(d[0] - 1, x + 1); ++i)
              if (!std::isfinite(vol.voxels[vol.grid.index(i, j, k)])) {
                finite_input = false;
                break;
              }
        h.overflow += finite_input;
      }
  return h;
}

}  // namespace

int run_check_gradient(const std::string& path, const std::string& device, double slab_mib, std::ostream& out) {
  const engine::Volume vol = io::load_any_volume(path);
  engine::ContextOptions co;
  co.device = device;
  auto ctx = engine::VulkanContext::create(co);
  if (!ctx) throw std::runtime_error("Vulkan: " + ctx.error);
  engine::GradientPass pass(**ctx.value);
  engine::GradientTimings gt;
  const auto gpu = pass.run(vol, &gt, std::uint64_t(slab_mib * 1024 * 1024));
  const auto t0 = std::chrono::steady_clock::now();
  const auto cpu = engine::compute_samples_cpu(vol);
  const double cpu_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const auto d = engine::compare_gradients(gpu, cpu);
  const GradientHealth gh = gradient_health(vol, cpu);
  std::array<double, 9> D = vol.direction;
  for (double& x : D) x += 0.0;  // print -0 as 0
  const core::Vec3 far = vol.index_to_physical(
      {double(vol.grid.dims[0] - 1), double(vol.grid.dims[1] - 1), double(vol.grid.dims[2] - 1)});
  out << std::setprecision(4) << "volume      " << path << " (" << vol.grid.dims[0] << "x" << vol.grid.dims[1]
            << "x" << vol.grid.dims[2] << ", " << vol.component_type << ", " << vol.reader << ")\n"
            << "spacing     " << vol.grid.spacing_m.x * 1e3 << " x " << vol.grid.spacing_m.y * 1e3 << " x "
            << vol.grid.spacing_m.z * 1e3 << " mm\n"
            << "orientation " << vol.orientation() << " (index axes x, y, z point toward; physical frame LPS)"
            << (vol.direction_is_identity ? ", direction identity" : "") << "\n";
  if (!vol.direction_is_identity)
    out << "direction   [" << D[0] << " " << D[1] << " " << D[2] << "; " << D[3] << " " << D[4] << " " << D[5]
              << "; " << D[6] << " " << D[7] << " " << D[8] << "] (columns: index axes in LPS)\n";
  out << "corners     voxel (0,0,0) at (" << vol.grid.origin_m.x * 1e3 << ", " << vol.grid.origin_m.y * 1e3
            << ", " << vol.grid.origin_m.z * 1e3 << ") mm, last voxel at (" << far.x * 1e3 << ", " << far.y * 1e3
            << ", " << far.z * 1e3 << ") mm (physical)\n"
            << "values      ";
  if (vol.finite_voxels > 0)
    out << "[" << vol.min_value << ", " << vol.max_value << "]";
  else
    out << "no finite voxel";
  out << "; NaN voxels " << vol.nan_voxels << ", Inf voxels " << vol.inf_voxels << " of " << vol.voxels.size()
            << "\n"
            << "device      " << (*ctx.value)->info().name << " (" << (*ctx.value)->info().type << ")\n"
            << "GPU         gradient " << gt.gradient_ms << " ms (" << (gt.gpu_timestamps ? "timestamps" : "wall")
            << ", " << gt.slabs << " slab(s)), submit-to-fence " << gt.submit_wall_ms << " ms, upload "
            << gt.upload_ms << " ms, download " << gt.download_ms << " ms\n"
            << "CPU         gradient " << cpu_ms << " ms (reference, one thread)\n"
            << "max |grad|  " << gh.max_norm << " [value/m] over finite gradients; non-finite gradients "
            << gh.nonfinite << " (" << gh.overflow << " from finite voxels: overflow)\n"
            << "max abs     gx " << d.max_abs[0] << "  gy " << d.max_abs[1] << "  gz " << d.max_abs[2]
            << "  value " << d.max_value_abs << "\n"
            << "max rel     gx " << d.max_abs[0] / std::max(d.max_gradient_norm, 1e-300) << "  gy "
            << d.max_abs[1] / std::max(d.max_gradient_norm, 1e-300) << "  gz "
            << d.max_abs[2] / std::max(d.max_gradient_norm, 1e-300) << "  (all " << d.max_rel
            << ", relative to max |grad|)\n";
  if (d.nonfinite) out << "mismatched non-finite samples: " << d.nonfinite << "\n";
  if (gh.nonfinite == 0 && gh.max_norm == 0.0)
    out << "note        the gradient is zero everywhere: a constant volume has no isosurface to feel\n";
  // A comparison is only meaningful on finite data with a finite gradient somewhere.
  std::vector<std::string> why;
  if (vol.nonfinite_voxels() > 0)
    why.push_back(std::to_string(vol.nonfinite_voxels()) + " non-finite voxels (NaN " + std::to_string(vol.nan_voxels) +
                  ", Inf " + std::to_string(vol.inf_voxels) + ")");
  if (gh.overflow > 0)
    why.push_back(std::to_string(gh.overflow) + " gradients overflow float from finite voxels");
  if (d.max_rel > 1e-6) {
    std::ostringstream r;
    r << "GPU and CPU differ by " << d.max_rel << " relative (tolerance 1e-6)";
    why.push_back(r.str());
  }
  if (why.empty()) {
    out << "PASS        tolerance 1e-6 relative\n";
    return 0;
  }
  out << "FAIL       ";
  for (const auto& w : why) out << " " << w << ";";
  out << "\n";
  return 3;
}

}  // namespace isotouch::bench
