#include "isotouch/eval/sweep.h"
#include "isotouch/io/vdb_io.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "isotouch/core/brick_field.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/gradient_pass.h"
#include "isotouch/sim/headless.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/sampling.h"
#include "isotouch/eval/surface_distance.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/engine/vk_context.h"

#ifndef ISOTOUCH_SOURCE_DIR
#error "ISOTOUCH_SOURCE_DIR must name the source tree (eval/CMakeLists.txt): the sweeps read its scenes"
#endif

namespace isotouch::eval {
using io::load_any_volume;
using io::load_scene;
using core::Vec3;
using io::Scene;
namespace {
namespace fs = std::filesystem;
using core::Vec3;

/// The published samples of `v`, with the background outside `iso` (outside the volume is
/// outside the object: core::FieldView).
std::shared_ptr<core::SampleField> samples(const engine::Volume& v, engine::VulkanContext* vk,
                                            const core::Isosurface& iso) {
  std::shared_ptr<core::SampleField> f;
  if (vk) {
    engine::GradientPass pass(*vk);
    f = std::make_shared<core::SampleField>(pass.run(v));
  } else {
    f = std::make_shared<core::SampleField>(engine::compute_samples_cpu(v));
  }
  f->background = core::outside_background(*f, iso);
  return f;
}

std::string scene_file(const std::string& name) {
  if (name.size() > 5 && name.substr(name.size() - 5) == ".json") return name;
  const std::string local = "scenes/" + name + ".json";
  if (fs::exists(local)) return local;
  return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / (name + ".json")).string();
}

}  // namespace

servo::HriParams reference_params(const SweepScene& s) {
  servo::HriParams p;
  p.tau = s.tau;
  p.inside = s.inside;
  p.stiffness_n_per_m = s.stiffness_n_per_m;
  p.damping_n_s_per_m = 0;
  p.plane_update_period = 1;
  p.rate_hz = s.rate_hz;
  p.force_limit_n = 1e3;  // no saturation in comparisons
  p.intersection = servo::Intersection::kBisection;
  p.intersection_steps = 40;
  p.normal = servo::NormalSource::kTrilinearExact;
  return p;
}

SweepScene prepare_sweep_scene(const std::string& name, engine::VulkanContext* vk, std::ostream& log,
                               std::optional<double> tau) {
  SweepScene s;
  s.name = name;
  sim::ScriptParams script;
  sim::SimDeviceParams dev;
  const auto names = eval::synthetic_scene_names();
  if (std::find(names.begin(), names.end(), name) != names.end()) {
    if (tau)
      throw std::invalid_argument("isovalue " + std::to_string(*tau) + " for " + name +
                                  ": an exact shape's truth is its own isovalue; only scene files (head, chest, "
                                  "a scene JSON) take another");
    eval::SyntheticScene syn = eval::make_synthetic_scene(name);
    s.description = syn.description;
    s.field = samples(syn.volume, vk, {syn.tau, s.inside});
    s.truth = std::move(syn.truth);
    s.tau = syn.tau;
    script = syn.script;
    s.hip = syn.hip_path;
    s.slide_begin = syn.slide_begin;
    s.slide_end = syn.slide_end;
  } else {
    Scene sc = load_scene(scene_file(name));
    if (tau) {
      if (!std::isfinite(*tau)) throw std::invalid_argument("isovalue for " + name + ": not a finite number");
      sc.hri.tau = *tau;
    }
    s.name = sc.name;
    s.description = sc.description;
    engine::Volume v;
    if (!sc.volume_path.empty()) v = load_any_volume(sc.volume_path);
    else if (sc.synthetic.kind == "sphere")
      v = engine::make_sphere(sc.synthetic.dims, sc.synthetic.spacing_m, sc.synthetic.radius_vox);
    else v = std::move(eval::make_synthetic_scene(sc.synthetic.kind).volume);
    s.field = samples(v, vk, {sc.hri.tau, sc.hri.inside});
    s.tau = sc.hri.tau;
    s.inside = sc.hri.inside;
    s.rate_hz = sc.hri.rate_hz;
    s.stiffness_n_per_m = sc.hri.stiffness_n_per_m;
    script = sc.script;
    dev = sc.device;
  }
  const Vec3& sp = s.field->grid.spacing_m;
  s.voxel_m = std::min({sp.x, sp.y, sp.z});

  if (!s.hip.empty()) {  // a prescribed path
    if (!s.truth) {
      servo::HriRenderer ref(reference_params(s));
      s.reference = playback(ref, s).ticks;
    }
    log << "scene " << s.name << ": prescribed path of " << s.hip.size() << " ticks\n";
    return s;
  }
  // Record the stroke once, with the reference renderer on the simulated device.
  servo::HriParams rp = reference_params(s);
  rp.damping_n_s_per_m = 1.0;
  rp.force_limit_n = 3.3;
  const sim::TouchScript ts = sim::make_touch_script(*s.field, rp, script);
  servo::TripleBuffer<core::SampleField> tb;
  tb.publish(s.field);
  servo::WorkspaceTransform xf;
  Vec3 p0, v0;
  ts.at(0, p0, v0);
  sim::SimDevice device(dev, p0);
  servo::HriRenderer rec(rp);
  const auto trace = sim::run_headless(tb, rec, device, xf, ts, s.rate_hz);
  s.hip.reserve(trace.size());
  for (const auto& r : trace) s.hip.push_back(r.hip_m);
  if (!s.truth) {
    servo::HriRenderer ref(reference_params(s));
    s.reference = playback(ref, s).ticks;
  }
  long contact = 0;
  for (const auto& r : trace) contact += r.contact;
  log << "scene " << s.name << ": " << s.hip.size() << " ticks recorded, " << contact << " in contact ("
      << (s.truth ? "truth: exact shape" : "truth: offline reference, HRI n = 1, exact root and gradient") << ")\n";
  return s;
}

Playback playback(servo::Renderer& r, const SweepScene& s) { return playback(r, s, *s.field); }

Playback playback(servo::Renderer& r, const SweepScene& s, const core::SampleField& f) {
  using clock = std::chrono::steady_clock;
  r.reset();
  Playback p;
  p.ticks.resize(s.hip.size());
  p.tick_ns.resize(s.hip.size());
  for (std::size_t k = 0; k < s.hip.size(); ++k) {
    const auto t0 = clock::now();
    p.ticks[k] = r.tick(f, s.hip[k]);
    const auto t1 = clock::now();
    p.tick_ns[k] = std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count();
  }
  return p;
}

ErrorFigures measure(const SweepScene& s, const Playback& p) {
  ErrorFigures e;
  const double K = s.stiffness_n_per_m;
  double se2 = 0, an2 = 0, fe2 = 0, sum_ns = 0;
  long n_angle = 0;
  std::vector<std::int64_t> ns = p.tick_ns;
  for (std::size_t k = 0; k < p.ticks.size(); ++k) {
    sum_ns += double(p.tick_ns[k]);
    const servo::HriTick& t = p.ticks[k];
    if (k > 0) {
      const double step = core::norm(t.force_n - p.ticks[k - 1].force_n);
      e.max_force_step_n = std::max(e.max_force_step_n, step);
      if (k > s.slide_begin && k < s.slide_end) e.max_force_step_slide_n = std::max(e.max_force_step_slide_n, step);
    }
    // Inside by more than half a voxel (not a one-tick difference at lift-off between the
    // trilinear surface and the exact one).
    const bool inside = s.truth ? s.truth->depth(s.hip[k]) > 0.5 * s.voxel_m
                                : s.reference[k].contact && s.reference[k].penetration_m > 0.5 * s.voxel_m;
    if (!t.contact) {
      if (k > 0 && p.ticks[k - 1].contact && inside) ++e.pop_throughs;
      continue;
    }
    ++e.contact_ticks;
    Vec3 n_true, f_true;
    double surf = 0;
    if (s.truth) {
      Vec3 cp, cn;
      s.truth->closest(t.vhip_m, cp, cn);
      surf = core::norm(t.vhip_m - cp);
      n_true = cn;
      // God-object on the true surface: the closest surface point to the HIP, if inside.
      Vec3 hp, hn;
      s.truth->closest(s.hip[k], hp, hn);
      f_true = s.truth->depth(s.hip[k]) > 0 ? (hp - s.hip[k]) * K : Vec3{};
    } else {
      // True distance to the trilinear isosurface (bounded search); a VHIP with no surface
      // within the search radius counts at that radius (a lower bound, never a made-up number).
      const SurfaceDistance d = distance_to_isosurface(*s.field, s.tau, t.vhip_m);
      surf = d.found ? d.distance_m : d.lower_bound_m;
      const servo::HriTick& r = s.reference[k];
      f_true = r.force_n;
      n_true = core::norm(r.force_n) > 1e-3 ? r.force_n / core::norm(r.force_n) : Vec3{};  // no angle without a reference force
    }
    se2 += surf * surf;
    fe2 += core::dot(t.force_n - f_true, t.force_n - f_true);
    const double fm = core::norm(t.force_n);
    if (fm > 1e-3 && core::norm(n_true) > 0) {
      const double c = std::clamp(core::dot(t.force_n / fm, n_true), -1.0, 1.0);
      const double a = std::acos(c) * 180.0 / M_PI;
      an2 += a * a;
      ++n_angle;
    }
  }
  if (!ns.empty()) {
    e.tick_ns_mean = sum_ns / double(ns.size());
    std::sort(ns.begin(), ns.end());
    e.tick_ns_p99 = double(ns[std::min(ns.size() - 1, std::size_t(0.99 * double(ns.size())))]);
  }
  if (e.contact_ticks) {
    e.surface_err_rms_m = std::sqrt(se2 / double(e.contact_ticks));
    e.force_err_rms_n = std::sqrt(fe2 / double(e.contact_ticks));
  }
  if (n_angle) e.angle_err_rms_deg = std::sqrt(an2 / double(n_angle));
  return e;
}

double median_ns_per_tick(servo::Renderer& r, const SweepScene& s, int warmup, int reps,
                          const std::atomic<bool>* cancel) {
  return median_ns_per_tick(r, s, *s.field, warmup, reps, cancel);
}

double median_ns_per_tick(servo::Renderer& r, const SweepScene& s, const core::SampleField& f, int warmup,
                          int reps, const std::atomic<bool>* cancel) {
  using clock = std::chrono::steady_clock;
  std::vector<double> per_tick;
  volatile double sink = 0;
  for (int i = 0; i < warmup + reps; ++i) {
    if (cancel && cancel->load()) return std::nan("");
    r.reset();
    const auto t0 = clock::now();
    for (const Vec3& h : s.hip) sink = sink + r.tick(f, h).force_n.x;
    const auto t1 = clock::now();
    if (i >= warmup)
      per_tick.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / double(s.hip.size()));
  }
  std::sort(per_tick.begin(), per_tick.end());
  return per_tick[per_tick.size() / 2];
}

std::vector<SnapshotVariant> snapshot_variants(const SweepScene& s) {
  using clock = std::chrono::steady_clock;
  std::vector<SnapshotVariant> out;
  out.push_back({"fp32 dense", s.field, core::snapshot_bytes(*s.field), 0.0, 0, 0});
  const core::Isosurface iso{s.tau, s.inside};
  for (const core::SampleFormat f : {core::SampleFormat::kFp32, core::SampleFormat::kFp16, core::SampleFormat::kUnorm16}) {
    std::vector<double> ms;
    std::shared_ptr<core::SampleField> b;
    for (int rep = 0; rep < 3; ++rep) {
      const auto t0 = clock::now();
      b = std::make_shared<core::SampleField>(core::make_bricked_field(core::bricked_input_from_dense(*s.field, iso), f));
      ms.push_back(std::chrono::duration<double, std::milli>(clock::now() - t0).count());
    }
    std::sort(ms.begin(), ms.end());
    b->version = s.field->version;
    SnapshotVariant v{std::string(core::to_string(f)) + " bricked", b, core::snapshot_bytes(*b), ms[1], 0, 0};
    v.bricks_total = b->bricks->table.size();
    v.bricks_active = b->bricks->table.size() - b->bricks->tiles.size();
    out.push_back(std::move(v));
  }
  return out;
}

FormatFigures compare_to_dense(const SweepScene& s, const Playback& p, const Playback& dense) {
  FormatFigures e;
  double se2 = 0, fd2 = 0, fsum = 0;
  long forced = 0, found = 0;
  for (std::size_t k = 0; k < p.ticks.size() && k < dense.ticks.size(); ++k) {
    const servo::HriTick& t = p.ticks[k];
    const servo::HriTick& d = dense.ticks[k];
    e.contact_ticks += t.contact;
    e.contact_ticks_dense += d.contact;
    e.contact_mismatch_ticks += t.contact != d.contact;
    if (d.contact) fsum += core::norm(d.force_n);
    if (t.contact || d.contact) {
      const double fd = core::norm(t.force_n - d.force_n);
      fd2 += fd * fd;
      e.force_diff_max_n = std::max(e.force_diff_max_n, fd);
      ++forced;
    }
    if (!t.contact) continue;
    // A VHIP with no surface within the search radius counts at that radius (a lower bound).
    const SurfaceDistance sd = distance_to_isosurface(*s.field, s.tau, t.vhip_m);
    const double dist = sd.found ? sd.distance_m : sd.lower_bound_m;
    se2 += dist * dist;
    e.surface_err_max_m = std::max(e.surface_err_max_m, dist);
    ++found;
  }
  if (found) e.surface_err_rms_m = std::sqrt(se2 / double(found));
  if (forced) e.force_diff_rms_n = std::sqrt(fd2 / double(forced));
  if (e.contact_ticks_dense) e.mean_force_dense_n = fsum / double(e.contact_ticks_dense);
  return e;
}

}  // namespace isotouch::eval
