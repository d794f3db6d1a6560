#include "isotouch/bench/link_stability.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <ostream>
#include <sstream>
#include <vector>

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/io/files.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/linked_contact.h"
#include "isotouch/sim/script.h"
#include <stdexcept>
#include <thread>

namespace isotouch::bench {
namespace {
namespace fs = std::filesystem;
using core::SampleField;
using core::Vec3;
using sim::LinkedContact;
using sim::LinkedContactResult;

constexpr double kWallK = 800;     // [N/m]: bone-like, the target
constexpr double kSearchLo = sim::kLinkSearchLoNPerM, kSearchHi = sim::kLinkSearchHiNPerM;
const Vec3 kP{0.016, 0.016, 0.010}, kUp{0, 0, 1};

struct Cell {
  double delay_s, rate_hz;
  double kmax, kmax_pc;
  bool k800_stable, k800_stable_pc;
  double k800_energy_j, k800_energy_pc_j;  // applied force's work on the device less its damper's loss [J]
  double settled_pc_m;                     // amplitude from 200 ms after contact, controller on [m]
  double stiffness_err_pc, rms_err_pc;     // slow press with the controller
  double served_min_s, served_max_s;       // pose-to-force round trip as the simulation served it [s]
};

LinkedContact press(double delay, double rate, bool pc, bool quick) {
  LinkedContact c;
  c.link.rate_hz = rate;
  c.link.round_trip_delay_s = delay;
  c.stiffness_n_per_m = kWallK;
  c.passivity_controller = pc;
  if (quick) c.duration_s = 1.0;
  return c;
}

LinkedContact slow_press(double delay, double rate, bool pc) {
  LinkedContact c = press(delay, rate, pc, false);
  c.motion = sim::LinkedMotion::kSlowPress;
  c.device.hand_stiffness_n_per_m = 300;  // a firm hand, as a slow deliberate press
  c.device.hand_damping_n_s_per_m = 5;
  c.duration_s = 3.0;
  return c;
}

/// RMS of (a - b) over RMS of b, over the common length.
double rms_relative(const std::vector<double>& a, const std::vector<double>& b) {
  double d = 0, s = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) d += (a[i] - b[i]) * (a[i] - b[i]), s += b[i] * b[i];
  return s > 0 ? std::sqrt(d / s) : 0;
}

/// What the hand presses: a field whose isosurface is tau = 0, inside above (as the link's
/// renderer reads it), the point the press aims at and the outward normal there (world [m]).
struct Surface {
  SampleField field;
  Vec3 p, n;
  bool wall = false;  ///< the flat wall sim::link_k_max presses
};

Cell measure(const Surface& at, double delay, double rate, bool quick, const std::vector<double>& reference) {
  Cell c{delay, rate, 0, 0, false, false, 0, 0, 0, 0, 0, 0, 0};
  const int it = quick ? 6 : sim::kLinkSearchIterations;
  if (at.wall) {  // the stiffness check's own function (sim::link_k_max): the table is its numbers
    const sim::LinkBound b = sim::link_k_max(press(delay, rate, false, quick), rate, delay, it);
    c.kmax = b.k_max_n_per_m;
    c.kmax_pc = b.k_max_with_pc_n_per_m;
  } else {
    c.kmax = sim::find_k_max_linked(at.field, at.p, at.n, press(delay, rate, false, quick), kSearchLo, kSearchHi, it);
    c.kmax_pc = sim::find_k_max_linked(at.field, at.p, at.n, press(delay, rate, true, quick), kSearchLo, kSearchHi, it);
  }
  for (bool pc : {false, true}) {
    const LinkedContact cfg = press(delay, rate, pc, quick);
    const LinkedContactResult r = sim::simulate_linked_contact(at.field, at.p, at.n, cfg);
    (pc ? c.k800_stable_pc : c.k800_stable) = r.stable(cfg);
    (pc ? c.k800_energy_pc_j : c.k800_energy_j) = r.device_energy_out_j;
    if (pc) c.settled_pc_m = r.settled_amplitude_m;
  }
  const LinkedContactResult s = sim::simulate_linked_contact(at.field, at.p, at.n, slow_press(delay, rate, true));
  c.stiffness_err_pc = s.max_force_error_ratio;
  c.rms_err_pc = rms_relative(s.force_trace_n, reference);
  c.served_min_s = s.round_trip_min_s;
  c.served_max_s = s.round_trip_max_s;
  return c;
}

std::string k_text(double k) {
  std::ostringstream o;
  if (k <= 0) return "<" + std::to_string(int(kSearchLo));  // below the search's floor
  o << std::setprecision(4) << k << (k >= kSearchHi * 0.999 ? "+" : "");
  return o.str();
}

std::string served_text(const Cell& c) {
  std::ostringstream o;
  o << std::setprecision(4) << c.served_min_s * 1e3;
  if (c.served_max_s > c.served_min_s + 1e-9) o << "-" << c.served_max_s * 1e3;
  return o.str();
}

void write_csv(const std::string& dir, const std::string& stem, const std::vector<Cell>& cells) {
  std::ostringstream csv;
  csv << "round_trip_ms,rate_hz,k_max_n_per_m,k_max_with_pc_n_per_m,k800_stable,k800_stable_with_pc,"
         "k800_device_energy_j,k800_device_energy_with_pc_j,k800_settled_amplitude_with_pc_mm,"
         "slow_press_stiffness_error_with_pc,slow_press_force_rms_error_vs_undelayed_with_pc,served_round_trip_min_ms,"
         "served_round_trip_max_ms\n"
      << std::setprecision(6);
  for (const Cell& c : cells)
    csv << c.delay_s * 1e3 << ',' << c.rate_hz << ',' << c.kmax << ',' << c.kmax_pc << ',' << c.k800_stable << ','
        << c.k800_stable_pc << ',' << c.k800_energy_j << ',' << c.k800_energy_pc_j << ',' << c.settled_pc_m * 1e3
        << ',' << c.stiffness_err_pc << ',' << c.rms_err_pc << ',' << c.served_min_s * 1e3 << ','
        << c.served_max_s * 1e3 << '\n';
  io::write_file_atomic((fs::path(dir) / (stem + ".csv")).string(), csv.str());
}

/// `title`: the markdown's title; `surface`: what is pressed, said after "on".
void write_md(const std::string& dir, const std::string& stem, const std::string& title, const std::string& surface,
              const std::vector<Cell>& cells, const std::string& reading) {
  const LinkedContact h = press(0, 100, false, false);
  std::ostringstream md;
  md << "# " << title << "\n\nPress (device mass " << h.device.mass_kg * 1e3 << " g, damping "
     << h.device.damping_n_s_per_m << " N s/m, hand spring " << h.device.hand_stiffness_n_per_m
     << " N/m without damping, " << h.push_force_n << " N pre-load, impact at " << h.approach_speed_m_s
     << " m/s) on " << surface << " rendered by HRI at the servo end of a simulated link (sim/linked_contact.h): poses go "
        "up and forces down at the link rate, each after half the round trip; the device end holds the last force "
        "over its own 1 kHz loop and runs the time-domain passivity controller (servo/port_passivity.h, one-port "
        "rule). Stable: no sustained oscillation of the device (late amplitude under "
     << LinkedContactResult::kStillAmplitudeM * 1e6 << " um or under " << LinkedContactResult::kDecayRatio
     << " of the early one) and the applied force's work on the device, less its own damper's loss, never exceeded "
     << 100 * LinkedContactResult::kEnergyTolerance << " % of the wall's stored energy. K_max: log "
        "bisection over " << kSearchLo << "-" << kSearchHi << " N/m (+: the search's top; <: below its floor, 0 in the csv). Slow press: the hand "
        "target moves in at " << slow_press(0, 100, true).press_speed_m_s * 1e3 << " mm/s (hand 300 N/m, 5 N s/m); "
        "stiffness error: the worst |mean F / (K mean depth) - 1| over 100 ms windows deeper than 1 mm; force RMS "
        "error: against the undelayed 1 kHz run without the controller. Served round trip: from a pose's sending to "
        "the device's receipt of the force rendered from it, min-max over the slow press's messages (each half is "
        "served at the device's next tick).\n\n" << reading << "\n\n"
     << "| round trip [ms] | served [ms] | rate [Hz] | K_max [N/m] | K_max with PC [N/m] | K = 800 stable | with PC | work on the device less "
        "its damper's loss at 800, with PC [J] | amplitude from +200 ms, PC [mm] | slow press stiffness error, PC | force RMS "
        "error vs undelayed, PC |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Cell& c : cells)
    md << "| " << c.delay_s * 1e3 << " | " << served_text(c) << " | " << c.rate_hz << " | " << k_text(c.kmax) << " | " << k_text(c.kmax_pc)
       << " | " << (c.k800_stable ? "yes" : "no") << " | " << (c.k800_stable_pc ? "yes" : "**no**") << " | "
       << std::setprecision(3) << c.k800_energy_pc_j << " | " << c.settled_pc_m * 1e3 << " | "
       << 100 * c.stiffness_err_pc << " % | " << 100 * c.rms_err_pc << " % |\n";
  io::write_file_atomic((fs::path(dir) / (stem + ".md")).string(), md.str());
}

/// The transparency target: the slow press's stiffness (mean force over mean depth,
/// 100 ms windows deeper than 1 mm) within 10 % of K with the controller on.
constexpr double kStiffnessTarget = 0.10;

bool meets_targets(const Cell& c) { return c.k800_stable_pc && c.stiffness_err_pc < kStiffnessTarget; }

std::string reading_of(const std::vector<Cell>& cells) {
  int off = 0, on = 0, transparent = 0;
  double worst_stiff = 0, worst_rms = 0, worst_amp = 0;
  for (const Cell& c : cells) {
    off += c.k800_stable;
    on += c.k800_stable_pc;
    transparent += c.stiffness_err_pc < kStiffnessTarget;
    worst_stiff = std::max(worst_stiff, c.stiffness_err_pc);
    worst_rms = std::max(worst_rms, c.rms_err_pc);
    worst_amp = std::max(worst_amp, c.settled_pc_m);
  }
  std::ostringstream o;
  o << std::setprecision(3) << "Reading it (computed from the rows): K = 800 N/m is stable in " << off << " of "
    << cells.size() << " cells without the controller and in " << on << " of " << cells.size()
    << " with it; with it the position's amplitude from 200 ms after contact is at most " << worst_amp * 1e3
    << " mm, the slow press's stiffness (100 ms means) is within " << 100 * worst_stiff << " % of K (target "
    << 100 * kStiffnessTarget << " %: met in " << transparent << " of " << cells.size()
    << " cells) and its force within " << 100 * worst_rms << " % RMS of the undelayed run's.";
  return o.str();
}


/// Every cell's rows on `at`, written to DIR/STEM.csv and .md. @return 0, or 4 if K = 800 with
/// the controller is unstable in some cell (or its slow press misses the stiffness target).
/// `label` starts each progress line.
int sweep(const Surface& at, const std::string& dir, const std::string& stem, const std::string& label,
          const std::string& title, const std::string& surface, bool quick, std::ostream& log) {
  const std::vector<double> reference =
      sim::simulate_linked_contact(at.field, at.p, at.n, slow_press(0, 1000, false)).force_trace_n;
  std::vector<Cell> cells;
  const std::vector<double> delays = {0, 1e-3, 2e-3, 5e-3, 10e-3, 20e-3}, rates = {100, 250, 500, 1000};
  for (double d : delays)
    for (double r : rates) {
      cells.push_back(measure(at, d, r, quick, reference));
      const Cell& c = cells.back();
      log << label << " " << std::setw(2) << cells.size() << "/" << delays.size() * rates.size() << "  round trip "
          << std::setw(2) << d * 1e3 << " ms  " << std::setw(4) << r << " Hz  K_max " << std::setw(7) << k_text(c.kmax)
          << " N/m, with PC " << std::setw(7) << k_text(c.kmax_pc) << " N/m; K = 800 " << (c.k800_stable ? "stable" : "unstable")
          << ", with PC " << (c.k800_stable_pc ? "stable" : "UNSTABLE") << std::setprecision(3) << " (slow press "
          << 100 * c.stiffness_err_pc << " % stiffness, " << 100 * c.rms_err_pc << " % RMS force error)\n";
    }
  const std::string reading = reading_of(cells);
  write_csv(dir, stem, cells);
  write_md(dir, stem, title, surface, cells, reading);
  log << reading << "\nwrote " << dir << "/" << stem << ".csv, " << stem << ".md\n";
  const bool all = std::all_of(cells.begin(), cells.end(), meets_targets);
  return all ? 0 : 4;
}

/// The scene's scan as the link's renderer reads it: values shifted (and turned, inside
/// below) so its isosurface is tau = 0 inside above, the samples on the CPU; the press aims
/// where the scene's script ray first meets it, along the outward normal there.
Surface scene_surface(const std::string& scene_path, std::string& what) {
  const io::Scene scene = io::load_scene(scene_path);
  if (scene.volume_path.empty())
    throw std::runtime_error(scene_path + ": field 'volume': a synthetic volume; `--scene` wants a scan");
  engine::Volume v = io::load_any_volume(scene.volume_path);
  const double tau = scene.hri.tau;
  const bool above = scene.hri.inside == core::InsideIs::kAbove;
  for (float& x : v.voxels) x = float(above ? double(x) - tau : tau - double(x));
  v.update_stats();
  Surface at{engine::compute_samples_cpu(v, std::max(1u, std::thread::hardware_concurrency())), {}, {}, false};
  servo::HriParams hp = scene.hri;
  hp.tau = 0;
  hp.inside = core::InsideIs::kAbove;
  sim::TouchScript script;
  try {
    script = sim::make_touch_script(at.field, hp, scene.script);
  } catch (const std::runtime_error& e) {  // it names the shifted field's isovalue 0: say the scene's
    std::ostringstream o;
    o << scene_path << ": field 'script': its ray does not find the isosurface at " << tau << " ("
      << (above ? "inside above" : "inside below") << ") to press: " << e.what();
    throw std::runtime_error(o.str());
  }
  at.p = script.contact_point_m;
  at.n = script.contact_normal;
  std::ostringstream o;
  o << std::setprecision(4) << "the isosurface of " << fs::path(scene.volume_path).filename().string() << " at "
    << tau << " (scene " << fs::path(scene_path).filename().string() << "), where its script's ray first meets it ("
    << at.p.x * 1e3 << ", " << at.p.y * 1e3 << ", " << at.p.z * 1e3 << ") mm grid-world, normal (" << at.n.x << ", "
    << at.n.y << ", " << at.n.z << ")";
  what = o.str();
  return at;
}

}  // namespace

int run_link_stability(const std::string& dir, bool quick, std::ostream& log) {
  fs::create_directories(dir);
  const Surface wall{sim::plane_field(kUp, kP), kP, kUp, true};
  return sweep(wall, dir, "link_stability", "link", "A wall through a delayed link", "a flat wall", quick, log);
}

int run_link_stability_on_scene(const std::string& scene_path, const std::string& dir, bool quick, std::ostream& log) {
  fs::create_directories(dir);
  std::string what;
  const Surface at = scene_surface(scene_path, what);
  log << "link scene: presses on " << what << "\n";
  return sweep(at, dir, "link_stability_scene", "link scene", "A scan through a delayed link", what, quick, log);
}

}  // namespace isotouch::bench
