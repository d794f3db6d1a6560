#include "trace_figures.h"
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
#include "names.h"
#include "pass_desc.h"

namespace isotouch::run {
namespace fs = std::filesystem;

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

}  // namespace isotouch::run
