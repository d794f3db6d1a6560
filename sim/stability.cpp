#include "isotouch/sim/stability.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/servo/passivity.h"
#include "isotouch/servo/sampling.h"

namespace isotouch::sim {

HeldContactResult simulate_held_contact(const SampleField& field, const Vec3& p0, const Vec3& normal,
                                        const HeldContact& cfg) {
  const Vec3 n = normalized_or(normal, {0, 0, 1});
  HriParams hp;
  hp.tau = 0;
  hp.stiffness_n_per_m = cfg.stiffness_n_per_m;
  hp.damping_n_s_per_m = cfg.virtual_damping_n_s_per_m;
  hp.plane_update_period = cfg.plane_update_period;
  hp.rate_hz = 1.0 / cfg.period_s;
  hp.force_limit_n = cfg.device.force_max_n;
  HriRenderer renderer(hp);
  PassivityController pc(cfg.period_s, cfg.passivity_controller, cfg.pc_alpha_max_n_s_per_m,
                         cfg.device.force_max_n);
  SimDevice dev(cfg.device, p0 + n * 2e-4);
  dev.set_state(p0 + n * 2e-4, n * -cfg.approach_speed_m_s);
  const double kh = cfg.device.hand_stiffness_n_per_m;
  const Vec3 target = p0 - n * (cfg.push_force_n / kh);
  const double d_eq = cfg.push_force_n / (cfg.stiffness_n_per_m + kh);
  const Vec3 x_eq = p0 - n * d_eq;
  const double k_total = cfg.stiffness_n_per_m + kh;
  const double m = cfg.device.mass_kg;

  HeldContactResult r;
  r.ticks = long(std::ceil(cfg.duration_s / cfg.period_s));
  r.tolerance_j = 0.01 * 0.5 * cfg.stiffness_n_per_m * d_eq * d_eq;
  const long w1a = long(0.2 * double(r.ticks)), w1b = long(0.45 * double(r.ticks)),
             w2a = long(0.75 * double(r.ticks));
  double e1 = 0, e2 = 0;
  bool touched = false;
  for (long k = 0; k < r.ticks; ++k) {
    const Vec3 x = dev.position();
    const HriTick out = renderer.tick(field, x);
    const Vec3 f = pc.step(x, out.force_n);
    if (!finite(f) || !finite(x)) r.nonfinite = true;
    r.max_force_n = std::max(r.max_force_n, norm(f));
    r.contact_ticks += out.contact;
    const double depth = -dot(x - p0, n);
    r.max_hip_depth_m = std::max(r.max_hip_depth_m, depth);
    if (out.contact) {
      touched = true;
      r.max_vhip_off_surface_m = std::max(r.max_vhip_off_surface_m, std::abs(dot(out.vhip_m - p0, n)));
    }
    if (touched && depth > 1e-6 && (!out.contact || !(norm(out.force_n) > 0))) ++r.inside_without_contact_ticks;
    dev.command_force(f);
    dev.step(cfg.period_s, target, {});
    const Vec3 v = dev.velocity();
    const double s = dot(dev.true_position() - x_eq, n);
    const double e = 0.5 * m * dot(v, v) + 0.5 * k_total * s * s;
    if (k >= w1a && k < w1b) e1 += e;
    if (k >= w2a) e2 += e;
    r.energy_out_j = std::max(r.energy_out_j, dev.rendered_work_j() - dev.damping_dissipated_j());
  }
  r.early_energy_j = e1 / double(std::max(1L, w1b - w1a));
  r.late_energy_j = e2 / double(std::max(1L, r.ticks - w2a));
  const double floor = 1e-6 * 0.5 * k_total * d_eq * d_eq;
  r.sustained_oscillation = r.late_energy_j > floor && r.late_energy_j > 0.5 * r.early_energy_j;
  r.gains_energy = r.energy_out_j > r.tolerance_j;
  return r;
}

double find_k_max(const SampleField& field, const Vec3& p0, const Vec3& normal, HeldContact cfg,
                  double lo, double hi, int iterations) {
  auto stable = [&](double k) {
    cfg.stiffness_n_per_m = k;
    return simulate_held_contact(field, p0, normal, cfg).stable();
  };
  if (!stable(lo)) return lo;
  if (stable(hi)) return hi;
  for (int i = 0; i < iterations; ++i) {
    const double mid = std::sqrt(lo * hi);
    (stable(mid) ? lo : hi) = mid;
  }
  return lo;
}

// ---------------------------------------------------------------------------------------
// Extreme cases
namespace {

std::string num(double v) {
  std::ostringstream s;
  s.precision(4);
  s << v;
  return s.str();
}

HriParams base_params() {
  HriParams p;
  p.tau = 0;
  p.stiffness_n_per_m = 800;
  p.damping_n_s_per_m = 1.0;
  p.plane_update_period = 1;
  p.rate_hz = 1000;
  p.force_limit_n = 3.3;
  return p;
}

bool ok_force(const HriTick& t, double limit) {
  return finite(t.force_n) && norm(t.force_n) <= limit * (1 + 1e-12);
}

const Vec3 kC{0.024, 0.024, 0.024};

ExtremeCase stiff_wall() {
  ExtremeCase c{"K = 1e5 N/m (50x the bound at 1 kHz, b = 1 N s/m)",
                "forces finite and <= F_max = 3.3 N at every tick; the contact is held: force whenever the HIP is "
                "behind the wall, the VHIP on the wall (< 1 um), the HIP no deeper than 2 mm; with and without "
                "the passivity controller", false, ""};
  const SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});
  HeldContact h;
  h.stiffness_n_per_m = 1e5;
  h.device.force_max_n = 3.3;
  const HeldContactResult off = simulate_held_contact(f, {0.016, 0.016, 0.010}, {0, 0, 1}, h);
  h.passivity_controller = true;
  const HeldContactResult on = simulate_held_contact(f, {0.016, 0.016, 0.010}, {0, 0, 1}, h);
  auto held = [](const HeldContactResult& r) {
    return r.contact_ticks > r.ticks / 4 && r.inside_without_contact_ticks == 0 && r.max_vhip_off_surface_m < 1e-6 &&
           r.max_hip_depth_m < 2e-3;
  };
  c.passed = !off.nonfinite && !on.nonfinite && off.max_force_n <= 3.3 + 1e-9 && on.max_force_n <= 3.3 + 1e-9 &&
             held(off) && held(on);
  auto holds = [](const HeldContactResult& r) {
    return ", " + std::to_string(r.contact_ticks) + "/" + std::to_string(r.ticks) + " ticks in contact, " +
           std::to_string(r.inside_without_contact_ticks) + " behind the wall without force, VHIP off the wall " +
           num(r.max_vhip_off_surface_m * 1e3) + " mm, HIP depth " + num(r.max_hip_depth_m * 1e3) + " mm";
  };
  auto amp = [&](const HeldContactResult& r) { return std::sqrt(2 * r.late_energy_j / (1e5 + 50)) * 1e3; };
  c.detail = "without PC: sustained oscillation " + std::string(off.sustained_oscillation ? "yes" : "no") +
             ", late amplitude ~" + num(amp(off)) + " mm, max |F| " + num(off.max_force_n) +
             " N; with PC: sustained " + (on.sustained_oscillation ? "yes" : "no") + ", late amplitude ~" +
             num(amp(on)) + " mm, max |F| " + num(on.max_force_n) + " N" +
             (on.sustained_oscillation && on.max_force_n >= 3.3 - 1e-9
                  ? " (the PC did not stop it while the force sat at F_max: saturation limits what it can dissipate)"
                  : "") +
             "; without PC" + holds(off) + "; with PC" + holds(on);
  return c;
}

ExtremeCase thin_shell_jump() {
  ExtremeCase c{"HIP jumps 5 cm in one tick across a 1-voxel shell",
                "the VHIP-HIP segment catches the shell: contact, force back outward, VHIP on the outer surface", false, ""};
  const Vec3 cs{0.048, 0.048, 0.048};
  const SampleField f = shell_field(cs, 0.030, 0.001);
  HriRenderer r(base_params());
  r.tick(f, cs + Vec3{0.040, 0, 0});
  const HriTick t = r.tick(f, cs + Vec3{-0.010, 0, 0});  // 5 cm in one tick, into the hollow
  const HriTick t2 = r.tick(f, cs + Vec3{-0.010, 0, 0});
  const double vhip_r = t.vhip_m.x - cs.x;
  c.passed = t.contact && t2.contact && t.force_n.x > 0 && ok_force(t, 3.3) && std::abs(vhip_r - 0.0305) < 1e-4;
  c.detail = "contact " + std::string(t.contact ? "yes" : "no") + ", F = (" + num(t.force_n.x) + ", " +
             num(t.force_n.y) + ", " + num(t.force_n.z) + ") N, VHIP at r = " + num(vhip_r * 1e3) +
             " mm (outer surface 30.5 mm), still in contact next tick: " + (t2.contact ? "yes" : "no");
  return c;
}

ExtremeCase start_deep_inside() {
  ExtremeCase c{"start deep inside", "no force while the HIP never came from outside (paper §3.1)", false, ""};
  const SampleField f = sphere_field(kC, 0.015);
  HriRenderer r(base_params());
  double fmax = 0;
  long contact = 0;
  for (int k = 0; k < 2000; ++k) {
    const HriTick t = r.tick(f, kC + Vec3{0.008 * std::sin(k * 0.01), 0.005 * std::cos(k * 0.013), 0});
    fmax = std::max(fmax, norm(t.force_n));
    contact += t.contact;
  }
  c.passed = fmax == 0 && contact == 0;
  c.detail = "2000 ticks moving inside: max |F| " + num(fmax) + " N, contact ticks " + std::to_string(contact);
  return c;
}

ExtremeCase leave_reenter() {
  ExtremeCase c{"leave and re-enter", "force in contact, none outside, force again on re-entry", false, ""};
  const SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});
  HriRenderer r(base_params());
  r.tick(f, {0.016, 0.016, 0.011});
  const HriTick a = r.tick(f, {0.016, 0.016, 0.009});
  const HriTick b = r.tick(f, {0.016, 0.016, 0.012});
  const HriTick b2 = r.tick(f, {0.017, 0.016, 0.012});
  const HriTick d = r.tick(f, {0.017, 0.016, 0.0095});
  c.passed = a.contact && !b.contact && !b2.contact && norm(b.force_n) == 0 && d.contact &&
             d.force_n.z > 0 && ok_force(d, 3.3);
  c.detail = "F in: " + num(a.force_n.z) + " N, out: " + num(norm(b.force_n)) + " N, re-entry: " + num(d.force_n.z) + " N";
  return c;
}

ExtremeCase bad_device_input() {
  ExtremeCase c{"NaN, Inf and huge positions from the device",
                "zero force and a fault flag; contact resumes when sane input returns", false, ""};
  const SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});
  HriRenderer r(base_params());
  r.tick(f, {0.016, 0.016, 0.011});
  bool ok = r.tick(f, {0.016, 0.016, 0.009}).contact;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  int faults = 0;
  for (const Vec3 bad : {Vec3{nan, 0, 0}, Vec3{0, inf, 0}, Vec3{0, 0, -inf}, Vec3{1e30, 0, 0}, Vec3{0, 1e12, 0}}) {
    const HriTick t = r.tick(f, bad);
    ok = ok && t.fault && norm(t.force_n) == 0;
    faults += t.fault;
  }
  // After a huge position the renderer restarts: the sane HIP (inside) gives no force ...
  const HriTick in = r.tick(f, {0.016, 0.016, 0.009});
  // ... until it comes from outside again.
  r.tick(f, {0.016, 0.016, 0.011});
  const HriTick again = r.tick(f, {0.016, 0.016, 0.009});
  ok = ok && !in.fault && !in.contact && again.contact && ok_force(again, 3.3);
  c.passed = ok;
  c.detail = std::to_string(faults) + "/5 bad inputs flagged with zero force; after recovery contact " +
             (again.contact ? "resumed" : "did not resume") + " (F = " + num(again.force_n.z) + " N)";
  return c;
}

ExtremeCase zero_gradient() {
  ExtremeCase c{"zero gradient at p", "a fallback normal, never NaN", false, ""};
  SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});
  for (auto& s : f.samples) s.gx = s.gy = s.gz = 0.f;
  HriRenderer r(base_params());
  r.tick(f, {0.016, 0.016, 0.011});
  const HriTick t = r.tick(f, {0.016, 0.016, 0.009});
  c.passed = t.contact && ok_force(t, 3.3) && finite(t.plane.n) && std::abs(norm(t.plane.n) - 1) < 1e-12;
  c.detail = "N = (" + num(t.plane.n.x) + ", " + num(t.plane.n.y) + ", " + num(t.plane.n.z) + "), |F| = " + num(norm(t.force_n)) + " N";
  return c;
}

ExtremeCase outside_volume() {
  ExtremeCase c{"HIP outside the volume", "border values are read (clamp to edge): no NaN; beyond max_reach_m a fault", false, ""};
  const SampleField f = sphere_field(kC, 0.015);
  HriRenderer r(base_params());
  bool ok = true;
  for (double d : {0.1, 0.5, 2.0, 9.0}) {
    const HriTick t = r.tick(f, kC + Vec3{d, -d, d} * 0.577);
    ok = ok && ok_force(t, 3.3) && !t.fault && norm(t.force_n) == 0;
  }
  const HriTick far = r.tick(f, kC + Vec3{20, 0, 0});
  c.passed = ok && far.fault && norm(far.force_n) == 0;
  c.detail = "0.1 m to 9 m away: zero force, no fault; 20 m away: fault " + std::string(far.fault ? "yes" : "no");
  return c;
}

ExtremeCase nan_voxels() {
  ExtremeCase c{"NaN voxels", "NaN reads count as outside; the force is never NaN", false, ""};
  SampleField f = sphere_field(kC, 0.015);
  for (int z = 36; z < 41; ++z)
    for (int y = 20; y < 30; ++y)
      for (int x = 16; x < 32; ++x) f.samples[f.grid.index(x, y, z)] = {NAN, NAN, NAN, NAN};
  HriRenderer r(base_params());
  long contact = 0;
  bool ok = true;
  for (int k = 0; k < 4000; ++k) {
    const double s = -0.012 + 0.024 * k / 4000.0;
    const Vec3 hip{kC.x + s, kC.y, kC.z + std::sqrt(std::max(0.0, 0.015 * 0.015 - s * s)) - 0.001 + 0.0015 * std::sin(k * 0.05)};
    const HriTick t = r.tick(f, hip);
    ok = ok && ok_force(t, 3.3) && finite(t.vhip_m);
    contact += t.contact;
  }
  c.passed = ok && contact > 100;
  c.detail = "4000-tick stroke across a 16x10x5 block of NaN voxels: " + std::to_string(contact) + " contact ticks, all forces finite";
  return c;
}

ExtremeCase isovalue_extremes() {
  // Outside the grid is outside every object (core::FieldView's background), so with tau
  // at the data minimum the whole box of voxel centres is the object and its faces are a
  // surface: the HIP is kept inside the box there (it starts inside: no force, §3.1).
  ExtremeCase c{"isovalue at the data minimum or maximum",
                "no surface to feel inside the data: no force, no NaN", false, ""};
  const SampleField f = sphere_field(kC, 0.015);
  float lo = 1e30f, hi = -1e30f;
  for (const auto& s : f.samples) {
    lo = std::min(lo, s.value);
    hi = std::max(hi, s.value);
  }
  bool ok = true;
  for (float tau : {lo, hi}) {
    HriParams p = base_params();
    p.tau = tau;
    HriRenderer r(p);
    const double a = tau == hi ? 0.03 : 0.018;  // [m]; the box is 47 mm wide around kC
    for (int k = 0; k < 500; ++k) {
      const HriTick t = r.tick(f, kC + Vec3{a * std::sin(k * 0.02), 0.02 * std::cos(k * 0.03), 0.01});
      ok = ok && ok_force(t, 3.3) && norm(t.force_n) == 0;
    }
  }
  c.passed = ok;
  c.detail = "tau = " + num(lo) + " (HIP inside the box) and " + num(hi) + " (leaving it): 500 ticks each, no force";
  return c;
}

ExtremeCase update_period_extremes() {
  ExtremeCase c{"n = 1 and n = 1000",
                "held still: the plane is updated exactly every n ticks; stroked along the sphere: contact "
                "rendered, forces bounded, the VHIP within 0.05 mm of the sphere (early updates keep a stale "
                "plane from carrying it off)", false, ""};
  const SampleField f = sphere_field(kC, 0.015);
  std::string detail;
  bool ok = true;
  for (int n : {1, 1000}) {
    HriParams p = base_params();
    p.plane_update_period = n;
    HriRenderer r(p);
    r.tick(f, kC + Vec3{0, 0, 0.017});
    // Held still 0.5 mm deep at the top: updates every n ticks, no other.
    std::vector<long> updates;
    for (long k = 0; k < 3000; ++k) {
      const HriTick t = r.tick(f, kC + Vec3{0, 0, 0.0145});
      ok = ok && t.contact && ok_force(t, 3.3);
      if (t.plane_update) updates.push_back(k);
    }
    bool period_ok = updates.size() >= 2;
    for (std::size_t i = 1; i < updates.size(); ++i) period_ok = period_ok && updates[i] - updates[i - 1] == n;
    period_ok = period_ok && long(updates.size()) == 1 + (2999 - updates.front()) / n;
    ok = ok && period_ok;
    // Stroked along the sphere, 0.5 mm deep.
    double err = 0;
    long contact = 0;
    for (int k = 0; k < 3000; ++k) {
      const double a = 0.5 * k / 3000.0;
      const HriTick t = r.tick(f, kC + Vec3{std::sin(a), 0, std::cos(a)} * 0.0145);
      ok = ok && ok_force(t, 3.3);
      if (t.contact) {
        ++contact;
        err = std::max(err, std::abs(norm(t.vhip_m - kC) - 0.015));
      }
    }
    ok = ok && contact == 3000 && err < 0.05e-3;
    detail += "n = " + std::to_string(n) + ": held, " + std::to_string(updates.size()) + " plane updates in 3000 ticks (" +
              (period_ok ? "every n" : "NOT every n") + "); stroke, " + std::to_string(contact) +
              " contact ticks, max VHIP error " + num(err * 1e3) + " mm; ";
  }
  c.passed = ok;
  c.detail = detail;
  return c;
}

ExtremeCase above_device_limit() {
  ExtremeCase c{"force above the device limit", "|F| saturates at F_max keeping its direction", false, ""};
  const Vec3 m = Vec3{1, 2, 2} / 3.0;
  const SampleField f = plane_field(m, {0.016, 0.016, 0.016});
  HriRenderer r(base_params());
  r.tick(f, Vec3{0.016, 0.016, 0.016} + m * 0.001);
  const HriTick t = r.tick(f, Vec3{0.016, 0.016, 0.016} - m * 0.01);  // K d = 8 N > 3.3 N
  c.passed = t.saturated && std::abs(norm(t.force_n) - 3.3) < 1e-9 && dot(t.force_n / norm(t.force_n), m) > 1 - 1e-9;
  c.detail = "K d = 8 N requested: |F| = " + num(norm(t.force_n)) + " N along N (cos = " + num(dot(t.force_n / norm(t.force_n), m)) + ")";
  return c;
}

}  // namespace

namespace {
using CaseFn = ExtremeCase (*)();
constexpr CaseFn kCases[] = {stiff_wall, thin_shell_jump, start_deep_inside, leave_reenter, bad_device_input,
                             zero_gradient, outside_volume, nan_voxels, isovalue_extremes,
                             update_period_extremes, above_device_limit};
}  // namespace

int extreme_case_count() { return int(sizeof(kCases) / sizeof(kCases[0])); }

ExtremeCase run_extreme_case(int i) { return kCases[i](); }

std::vector<ExtremeCase> run_extreme_cases() {
  std::vector<ExtremeCase> out;
  for (int i = 0; i < extreme_case_count(); ++i) out.push_back(run_extreme_case(i));
  return out;
}

long random_tick_property(long ticks, unsigned seed, double& max_ratio, std::string* detail) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<SampleField> fields;
  fields.push_back(plane_field({0.3, -0.2, 1}, kC, 48));
  fields.push_back(sphere_field(kC, 0.015));
  fields.push_back(shell_field(kC, 0.015, 0.001, 48));
  fields.push_back(sphere_field(kC, 0.015));
  for (std::size_t i = 0; i < fields[3].samples.size(); i += 7) fields[3].samples[i] = {NAN, NAN, NAN, NAN};
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  long bad = 0, nonfinite = 0, above = 0, force_outside = 0, off_normal = 0, pulling = 0, vhip_off = 0, fault_force = 0;
  max_ratio = 0;
  const long per_run = 2000;
  for (long done = 0; done < ticks;) {
    const SampleField& f = fields[std::size_t(u(rng) * double(fields.size())) % fields.size()];
    HriParams p;
    p.tau = u(rng) < 0.1 ? (u(rng) - 0.5) * 60.0 : 0.0;
    p.inside = u(rng) < 0.2 ? InsideIs::kBelow : InsideIs::kAbove;
    p.stiffness_n_per_m = std::pow(10.0, 1 + 5 * u(rng));
    p.damping_n_s_per_m = 10 * u(rng);
    p.plane_update_period = 1 + int(std::pow(1000.0, u(rng)));
    p.rate_hz = u(rng) < 0.5 ? 1000 : 10000;
    p.force_limit_n = 0.1 + 20 * u(rng);
    HriRenderer r(p);
    Vec3 hip = kC + Vec3{u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5} * 0.04;
    for (long k = 0; k < per_run && done < ticks; ++k, ++done) {
      const double roll = u(rng);
      Vec3 x;
      if (roll < 0.002) x = {nan, 0, 0};
      else if (roll < 0.004) x = {0, inf, -inf};
      else if (roll < 0.006) x = {1e300, -1e300, 1e300};
      else if (roll < 0.02) x = hip = kC + Vec3{u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5} * 0.1;  // jump
      else x = hip = hip + Vec3{u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5} * 4e-4;
      const HriTick t = r.tick(f, x);
      const double fn = norm(t.force_n);
      bool b = false;
      if (!finite(t.force_n) || !finite(t.vhip_m)) b = true, ++nonfinite;
      if (!(fn <= p.force_limit_n * (1 + 1e-12))) b = true, ++above;
      if (!t.contact && fn != 0) b = true, ++force_outside;
      if (t.fault && fn != 0) b = true, ++fault_force;
      if (t.contact && finite(t.force_n)) {
        const Vec3& N = t.plane.n;
        const double fN = dot(t.force_n, N);
        if (norm(t.force_n - N * fN) > 1e-9 * fn + 1e-12) b = true, ++off_normal;
        if (fN < -1e-12) b = true, ++pulling;
        if (!(std::abs(dot(t.vhip_m - t.plane.p, N)) <= 1e-9)) b = true, ++vhip_off;
      }
      bad += b;
      if (std::isfinite(fn)) max_ratio = std::max(max_ratio, fn / p.force_limit_n);
    }
  }
  if (detail)
    *detail = std::to_string(nonfinite) + " non-finite, " + std::to_string(above) + " above F_max, " +
              std::to_string(force_outside) + " with force but no contact, " + std::to_string(fault_force) +
              " faults with force, " + std::to_string(off_normal) + " not along N, " + std::to_string(pulling) +
              " pulling, " + std::to_string(vhip_off) + " with the VHIP off the plane";
  return bad;
}

}  // namespace isotouch::sim
