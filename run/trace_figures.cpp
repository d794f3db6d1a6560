#include "isotouch/run/trace_figures.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include "isotouch/core/field_view.h"
#include "isotouch/run/names.h"
#include "isotouch/engine/pass_desc.h"

namespace isotouch::run {
namespace {

/// Sums over the contact ticks, turned into RMS figures at the end.
struct ContactSums {
  double err2 = 0, fo2 = 0, raw2 = 0, fsum = 0;  // fo2: over the ticks where it is a distance
  long found = 0, raw_found = 0;
};

/// With filters in the pass list: the unfiltered data's samples (gradient only), to see how
/// far smoothing moved the surface; none without filters (m.has_unfiltered says which).
std::optional<core::SampleField> unfiltered_field(const SceneSetup& setup, RunMetrics& m) {
  for (const auto& p : m.passes)
    if (p.kind == engine::PassKind::Gaussian || p.kind == engine::PassKind::Closing) m.has_unfiltered = true;
  if (!m.has_unfiltered) return std::nullopt;
  engine::ChainOutput out = engine::run_chain_cpu(setup.volume, {engine::PassDesc::gradient()});
  out.samples->background = setup.truth->background;
  return std::move(out.samples);
}

/// The stroke phase (t_stroke <= t < t_lift) and the lift-off (t >= t_lift) of one tick.
void stroke_and_lift(const sim::TraceRow& r, const sim::TouchScript& script, RunMetrics& m) {
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
}

/// Steps of |F| and of the force vector between two consecutive contact ticks.
void contact_steps(const sim::TraceRow& r, const sim::TraceRow& last, double f, RunMetrics& m) {
  const double step = std::abs(f - core::norm(last.force_n));
  if (step > m.max_force_step_n) {
    m.max_force_step_n = step;
    m.max_force_step_t_s = r.t_s;
  }
  const double vstep = core::norm(r.force_n - last.force_n);
  if (vstep > m.max_force_vector_step_n) {
    m.max_force_vector_step_n = vstep;
    m.max_force_vector_step_t_s = r.t_s;
  }
}

/// The surface error of the tool from a distance d [m] of the VHIP to the isosurface: with a
/// spherical tool of radius r the VHIP is the tool's centre, r outside the surface when the
/// tool's surface rests on it, so the error is |d - r|, and d + r with the centre inside the
/// object. A point tool (r = 0): d.
double tool_error(double d, bool centre_inside, double r) {
  if (!(r > 0)) return d;
  return centre_inside ? d + r : std::abs(d - r);
}

/// The VHIP inside the isosurface of `field` (the scene's isovalue and inside).
bool vhip_inside(const core::SampleField& field, const core::Isosurface& iso, const sim::TraceRow& r) {
  return iso.contains(core::FieldView(field).value(r.vhip_m));
}

/// One contact tick's first-order estimate into the figures where it is a distance; counted
/// as left out where it is not.
void add_first_order(double fo, RunMetrics& m, ContactSums& s) {
  const std::optional<double> d = first_order_as_distance(fo, m.first_order_bound_m);
  if (!d) {
    ++m.first_order_left_out_ticks;
    return;
  }
  ++m.first_order_kept_ticks;
  s.fo2 += *d * *d;
  m.first_order_err_max_m = std::max(m.first_order_err_max_m, *d);
}

/// One contact tick's surface error (true distance, first-order estimate) into the figures.
void add_error(SurfaceDistance d, double fo, bool inside, double r, RunMetrics& m, ContactSums& s) {
  if (d.found) d.distance_m = tool_error(d.distance_m, inside, r);
  m.surface_search_radius_m = std::max(m.surface_search_radius_m, d.searched_radius_m);
  if (d.found) {
    ++s.found;
    s.err2 += d.distance_m * d.distance_m;
    m.surface_err_max_m = std::max(m.surface_err_max_m, d.distance_m);
  } else {
    ++m.surface_err_not_found_ticks;
  }
  add_first_order(tool_error(fo, inside, r), m, s);
}

/// The VHIP's distance from the unfiltered data's isosurface on one contact tick.
void add_unfiltered_error(const core::SampleField& unfiltered, const core::Isosurface& iso, double tool_r,
                          const sim::TraceRow& r, RunMetrics& m, ContactSums& s) {
  const SurfaceDistance du = distance_to_isosurface(unfiltered, iso.tau, r.vhip_m);
  if (!du.found) return;
  const double e = tool_error(du.distance_m, tool_r > 0 && vhip_inside(unfiltered, iso, r), tool_r);
  ++s.raw_found;
  s.raw2 += e * e;
  m.unfiltered_err_max_m = std::max(m.unfiltered_err_max_m, e);
}

/// Steps of |F| that the contact-only figure cannot see: a drop to zero from contact (every
/// release, inside the object or not), and any step between two consecutive ticks.
void release_and_any_steps(const std::vector<sim::TraceRow>& trace, RunMetrics& m) {
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

/// Tick wall times: median, p99, max and mean [ns].
void tick_times(const std::vector<sim::TraceRow>& trace, RunMetrics& m) {
  std::vector<std::int64_t> ns;
  ns.reserve(trace.size());
  double sum_ns = 0;
  for (const auto& r : trace) {
    ns.push_back(r.tick_ns);
    sum_ns += double(r.tick_ns);
  }
  const std::vector<double> ns_d(ns.begin(), ns.end());
  m.tick_ns_median = ns.empty() ? 0 : percentile(ns_d, 0.5);
  m.tick_ns_p99 = ns.empty() ? 0 : percentile(ns_d, 0.99);
  m.tick_ns_max = ns.empty() ? 0 : double(*std::max_element(ns.begin(), ns.end()));
  m.tick_ns_mean = ns.empty() ? 0 : sum_ns / double(ns.size());
}

/// The ticks of the drilling phase: each run of at least 3 published brush edits whose
/// ticks are `period` apart, from its first edit to one period after its last, as [from, to).
std::vector<std::pair<long, long>> drilling_runs(const EditDriver& edits, long period) {
  std::vector<long> ticks;
  for (const EditRow& r : edits.rows)
    if (r.event.kind == EditEvent::Kind::kBrush && r.outcome.published) ticks.push_back(r.event.tick);
  std::sort(ticks.begin(), ticks.end());
  std::vector<std::pair<long, long>> runs;
  for (std::size_t i = 0; i < ticks.size();) {
    std::size_t j = i;
    while (j + 1 < ticks.size() && ticks[j + 1] - ticks[j] == period) ++j;
    if (j - i + 1 >= 3) runs.push_back({ticks[i], ticks[j] + period});
    i = j + 1;
  }
  return runs;
}

/// The ripple (RunMetrics::ripple_n): |F| sent minus its moving median over one edit
/// period (the scene's every_ticks, whatever the servo does with edits), within each
/// drilling run, and the amplitude of that at 1 / period: 2 / N times the modulus of its
/// discrete Fourier sum at that frequency over the N drilling ticks (the runs are whole
/// periods long, so no other harmonic leaks in).
void edit_ripple(const std::vector<sim::TraceRow>& trace, const EditDriver& edits, RunMetrics& m) {
  const long period = edits.every_ticks();
  if (period < 2) return;
  double re = 0, im = 0;
  long n = 0;
  std::vector<double> f, window;
  for (const auto& [from, to] : drilling_runs(edits, period)) {
    if (from < 0 || to > long(trace.size())) continue;
    f.clear();
    for (long k = from; k < to; ++k) f.push_back(core::norm(trace[std::size_t(k)].force_n));
    for (long i = 0; i < long(f.size()); ++i) {
      const long lo = std::clamp(i - period / 2, 0L, long(f.size()) - period);
      window.assign(f.begin() + lo, f.begin() + lo + period);
      std::nth_element(window.begin(), window.begin() + period / 2, window.end());
      double med = window[std::size_t(period / 2)];
      if (period % 2 == 0) med = 0.5 * (med + *std::max_element(window.begin(), window.begin() + period / 2));
      const double phase = 2.0 * M_PI * double((from + i) % period) / double(period);
      re += (f[std::size_t(i)] - med) * std::cos(phase);
      im -= (f[std::size_t(i)] - med) * std::sin(phase);
    }
    n += long(f.size());
  }
  if (n == 0) return;
  m.ripple_n = 2.0 / double(n) * std::hypot(re, im);
  m.ripple_ticks = n;
}

}  // namespace

void DirectionSteps::add(double t_s, bool contact, const core::Vec3& force_n) {
  if (!contact) {
    have_last_ = false;
    return;
  }
  const double f = core::norm(force_n);
  if (!(f > 0)) return;
  if (have_last_) {
    const double c = std::clamp(core::dot(force_n, last_) / (f * core::norm(last_)), -1.0, 1.0);
    const double a = std::acos(c) * 180.0 / M_PI;
    sum2_ += a * a;
    ++pairs;
    if (a > max_deg) {
      max_deg = a;
      max_t_s = t_s;
    }
  }
  last_ = force_n;
  have_last_ = true;
}

double DirectionSteps::rms_deg() const { return pairs ? std::sqrt(sum2_ / double(pairs)) : 0.0; }

namespace {

/// The length of the volume's box [m], corner to corner.
double volume_diagonal_m(const engine::Volume& v) {
  const double x = v.grid.dims[0] * v.grid.spacing_m.x, y = v.grid.dims[1] * v.grid.spacing_m.y,
               z = v.grid.dims[2] * v.grid.spacing_m.z;
  return std::sqrt(x * x + y * y + z * z);
}

}  // namespace

std::optional<double> first_order_as_distance(double estimate_m, double bound_m) {
  if (!std::isfinite(estimate_m) || !(estimate_m <= bound_m)) return std::nullopt;
  return estimate_m;
}

std::pair<long, long> trace_figures(const std::vector<sim::TraceRow>& trace, const SceneSetup& setup,
                                    const EditDriver* edits, RunMetrics& m) {
  const double tau = setup.hri.tau, tool_r = setup.hri.tool_radius_m;
  const core::Isosurface iso = setup.live.iso;
  const core::SampleField& truth = *setup.truth;
  m.ticks = long(trace.size());
  m.first_order_bound_m = volume_diagonal_m(setup.volume);
  ContactSums s;
  DirectionSteps dirs;
  const std::optional<core::SampleField> unfiltered = unfiltered_field(setup, m);
  const sim::TraceRow* prev = nullptr;
  for (const auto& r : trace) {
    m.plane_updates += r.plane_update;
    m.saturated_ticks += r.saturated;
    m.fault_ticks += r.fault;
    const sim::TraceRow* last = prev;
    prev = &r;
    stroke_and_lift(r, setup.script, m);
    dirs.add(r.t_s, r.contact, r.force_n);
    if (!r.contact) continue;
    ++m.contact_ticks;
    const double f = core::norm(r.force_n);
    m.contact_ticks_under_95pct_limit += f < 0.95 * setup.hri.force_limit_n;
    if (last && last->contact) contact_steps(r, *last, f, m);
    s.fsum += f;
    m.max_force_n = std::max(m.max_force_n, f);
    m.max_penetration_m = std::max(m.max_penetration_m, r.penetration_m);
    if (edits && r.version > 1) {  // the surface moved: measured against the edited volume the tick read
      ++m.edits.contact_ticks_after_edit;
      const auto it = edits->edited_distance.find(long(&r - trace.data()));
      if (it != edits->edited_distance.end())
        add_error(it->second.d, it->second.first_order_m, it->second.vhip_inside, tool_r, m, s);
      continue;
    }
    if (unfiltered) add_unfiltered_error(*unfiltered, iso, tool_r, r, m, s);
    // True distance of the VHIP from the isosurface of the trilinear field (bounded search).
    add_error(distance_to_isosurface(truth, tau, r.vhip_m), first_order_distance(truth, tau, r.vhip_m),
              tool_r > 0 && vhip_inside(truth, iso, r), tool_r, m, s);
  }
  release_and_any_steps(trace, m);
  if (edits) edit_ripple(trace, *edits, m);
  tick_times(trace, m);
  if (m.contact_ticks) {
    m.mean_contact_force_n = s.fsum / double(m.contact_ticks);
  }
  if (m.first_order_kept_ticks) m.first_order_err_rms_m = std::sqrt(s.fo2 / double(m.first_order_kept_ticks));
  if (s.found) m.surface_err_rms_m = std::sqrt(s.err2 / double(s.found));
  m.force_dir_step_rms_deg = dirs.rms_deg();
  m.force_dir_step_max_deg = dirs.max_deg;
  m.force_dir_step_max_t_s = dirs.max_t_s;
  if (s.raw_found) m.unfiltered_err_rms_m = std::sqrt(s.raw2 / double(s.raw_found));
  return {s.found, s.raw_found};
}

}  // namespace isotouch::run
