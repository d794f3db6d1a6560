#include "isotouch/bench/stability_report.h"


#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/io/files.h"
#include "isotouch/sim/stability.h"

namespace isotouch::bench {
using io::draw_with_gnuplot;
using io::gnuplot_quote;
using io::temp_name;
using io::write_file_atomic;
using sim::colgate_k_max;
using sim::find_k_max;
using sim::plane_field;
using sim::random_tick_property;
using sim::run_extreme_cases;
using sim::sphere_field;
using core::SampleField;
using core::Vec3;
using sim::ExtremeCase;
using sim::HeldContact;
namespace {
namespace fs = std::filesystem;
using namespace servo;

struct Row {
  std::string shape;
  double T, b, B, bound, kmax, kmax_pc;
};

std::string csv_escape(const std::string& s) {
  std::string o = "\"";
  for (char c : s) o += c == '"' ? std::string("\"\"") : std::string(1, c);
  return o + "\"";
}
}  // namespace

int run_stability(const std::string& dir, bool quick, std::ostream& log) {
  fs::create_directories(dir);
  const Vec3 wall_p{0.016, 0.016, 0.010}, up{0, 0, 1};
  const SampleField wall = plane_field(up, wall_p);
  const Vec3 sc{0.024, 0.024, 0.024};
  const double sphere_r = 0.015;
  const SampleField sphere = sphere_field(sc, sphere_r);
  const Vec3 sphere_p = sc + Vec3{0, 0, sphere_r};

  struct Damp {
    double b, B;
  };
  const std::vector<double> periods = {1e-3, 2.5e-4, 1e-4};
  const std::vector<Damp> damps = {{0.5, 0}, {1.0, 0}, {2.0, 0}, {1.0, 0.3}};
  std::vector<Row> rows;
  const int total = int(periods.size() * damps.size() * 2);
  int done = 0;
  for (const char* shape : {"wall", "sphere"}) {
    const bool is_wall = std::string(shape) == "wall";
    for (double T : periods)
      for (const Damp& d : damps) {
        HeldContact h;
        h.period_s = T;
        h.device.damping_n_s_per_m = d.b;
        h.virtual_damping_n_s_per_m = d.B;
        if (quick) h.duration_s = 1.5;
        h.pc_alpha_max_n_s_per_m = std::min(50.0, 0.5 * h.device.mass_kg / T);
        const double bound = colgate_k_max(d.b, d.B, T);
        const int it = quick ? 8 : 14;
        const SampleField& f = is_wall ? wall : sphere;
        const Vec3& p = is_wall ? wall_p : sphere_p;
        const double kmax = find_k_max(f, p, up, h, bound / 8, bound * 8, it);
        h.passivity_controller = true;
        const double kmax_pc = find_k_max(f, p, up, h, bound / 8, bound * 64, it);
        rows.push_back({shape, T, d.b, d.B, bound, kmax, kmax_pc});
        ++done;
        log << "stability " << std::setw(2) << done << "/" << total << "  " << std::setw(6) << shape << "  T = "
            << std::setw(6) << T * 1e3 << " ms  b = " << d.b << "  B = " << d.B << "  bound " << std::setw(7)
            << bound << " N/m  K_max " << std::setw(8) << std::setprecision(5) << kmax << " N/m  ratio "
            << std::setprecision(3) << kmax / bound << "  (with passivity controller: "
            << std::setprecision(5) << kmax_pc << (kmax_pc >= bound * 64 * 0.999 ? "+" : "") << " N/m)\n";
      }
  }

  std::ostringstream csv;
  csv << "shape,T_s,b_n_s_per_m,B_n_s_per_m,k_bound_n_per_m,k_max_n_per_m,ratio,k_max_with_pc_n_per_m\n";
  csv << std::setprecision(8);
  for (const Row& r : rows)
    csv << r.shape << ',' << r.T << ',' << r.b << ',' << r.B << ',' << r.bound << ',' << r.kmax << ','
        << r.kmax / r.bound << ',' << r.kmax_pc << '\n';
  write_file_atomic((fs::path(dir) / "stability.csv").string(), csv.str());

  log << "extreme cases:\n";
  const std::vector<ExtremeCase> cases = run_extreme_cases();
  double ratio = 0;
  std::string prop_detail;
  const long bad = random_tick_property(quick ? 100000 : 1000000, 2024, ratio, &prop_detail);
  const std::string prop_expect = "finite, |F| <= F_max, zero force without contact and on faults, in contact F along N, "
                                  "pushing, VHIP on the plane";
  std::ostringstream ec;
  ec << "case,expectation,result,detail\n";
  bool all = bad == 0;
  for (const auto& c : cases) {
    all = all && c.passed;
    ec << csv_escape(c.name) << ',' << csv_escape(c.expectation) << ',' << (c.passed ? "pass" : "FAIL") << ','
       << csv_escape(c.detail) << '\n';
    log << "  " << (c.passed ? "pass " : "FAIL ") << c.name << ": " << c.detail << "\n";
  }
  const std::string prop = std::to_string(quick ? 100000 : 1000000) + " random ticks: " + std::to_string(bad) +
                           " broke a property (" + prop_detail + "); max |F|/F_max = " + std::to_string(ratio);
  ec << csv_escape("random ticks (property)") << ',' << csv_escape(prop_expect) << ','
     << (bad == 0 ? "pass" : "FAIL") << ',' << csv_escape(prop) << '\n';
  log << "  " << (bad == 0 ? "pass " : "FAIL ") << prop << "\n";
  write_file_atomic((fs::path(dir) / "extreme_cases.csv").string(), ec.str());

  // Plot: measured K_max against the bound, one colour per T, wall and sphere markers.
  const std::string png = fs::absolute(fs::path(dir) / "stability.png").string();
  const std::string data = fs::absolute(fs::path(dir) / "stability.csv").string();
  std::ostringstream g;
  g << "set datafile separator ','\nset terminal pngcairo size 900,700 font 'Sans,10'\n"
    << "set termoption noenhanced\n"
    << "set output " << gnuplot_quote(temp_name(png)) << "\n"
    << "set title 'Held contact on the HRI wall: measured K_max against 2 (b - |B|) / T'\n"
    << "set logscale xy\nset grid\nset key top left\n"
    << "set xlabel 'Colgate-Schenkel bound 2 (b - |B|) / T [N/m]'\nset ylabel 'measured K_max [N/m]'\n"
    << "plot x with lines dt 2 lc rgb '#555555' title 'K_max = bound'";
  const char* colours[] = {"#c0392b", "#2471a3", "#229954"};
  for (std::size_t i = 0; i < periods.size(); ++i) {
    const double T = periods[i];
    for (const char* shape : {"wall", "sphere"}) {
      const bool w = std::string(shape) == "wall";
      g << ", " << gnuplot_quote(data) << " every ::1 using ($2 > " << T * 0.999 << " && $2 < " << T * 1.001
        << " && strcol(1) eq '" << shape << "' ? $5 : 1/0):6 with points pt " << (w ? 7 : 8) << " ps " << (w ? 1.4 : 2.6) << " lc rgb '"
        << colours[i] << "' title 'T = " << T * 1e3 << " ms, " << shape << "'";
    }
  }
  g << "\n";
  const bool plotted = draw_with_gnuplot((fs::path(dir) / "stability.gp").string(), g.str(), {png}).empty();

  // Conclusions computed from the rows: each sentence says what was compared.
  const HeldContact h0;
  double b0_lo = 1e300, b0_hi = 0, bp_lo = 1e300, bp_hi = 0, bp_bound_lo = 1e300, bp_bound_hi = 0, shape_diff = 0;
  int b0_rows = 0, bp_rows = 0, shape_pairs = 0;
  for (const Row& r : rows) {
    if (r.B == 0) {
      b0_lo = std::min(b0_lo, r.kmax / r.bound);
      b0_hi = std::max(b0_hi, r.kmax / r.bound);
      ++b0_rows;
    } else {
      const double plus = 2 * (r.b + std::abs(r.B)) / r.T;
      bp_lo = std::min(bp_lo, r.kmax / plus);
      bp_hi = std::max(bp_hi, r.kmax / plus);
      bp_bound_lo = std::min(bp_bound_lo, r.kmax / r.bound);
      bp_bound_hi = std::max(bp_bound_hi, r.kmax / r.bound);
      ++bp_rows;
    }
    if (r.shape != "sphere") continue;
    for (const Row& w : rows)
      if (w.shape == "wall" && w.T == r.T && w.b == r.b && w.B == r.B) {
        shape_diff = std::max(shape_diff, std::abs(r.kmax - w.kmax) / w.kmax);
        ++shape_pairs;
      }
  }
  auto pct = [](double x) {
    std::ostringstream o;
    o << std::setprecision(3) << 100 * x << " %";
    return o.str();
  };
  // The log bisection brackets K_max to a factor 64^(1 / 2^it) (< 2 % here); "on the bound"
  // allows 25 % for the criteria (energy thresholds, finite run) rather than the search.
  const bool on_bound = b0_rows && b0_lo >= 0.8 && b0_hi <= 1.25;
  std::ostringstream reading;
  reading << std::setprecision(3) << "Reading it (computed from the rows above): with B = 0, K_max / bound ranges from "
          << b0_lo << " to " << b0_hi << " over " << b0_rows << " rows, so the measured K_max "
          << (on_bound ? "sits on the bound (within 25 %)" : "does not sit on the bound (more than 25 % off in some row)")
          << ". ";
  if (bp_rows)
    reading << "With virtual damping B > 0 (" << bp_rows << " rows), K_max / bound ranges from " << bp_bound_lo << " to "
            << bp_bound_hi << " and K_max / (2 (b + |B|) / T) from " << bp_lo << " to " << bp_hi
            << (bp_lo >= 0.8 && bp_hi <= 1.25
                    ? ": the held contact stays stable up to about 2 (b + |B|) / T, so the bound, which charges |B| "
                      "against b, is conservative for this damper. "
                    : (bp_hi < 1.25 && bp_bound_lo >= 0.8 ? ": the bound holds. " : ". "));
  if (shape_pairs)
    reading << "Sphere against wall at equal T, b, B (" << shape_pairs << " pairs): K_max differs by at most "
            << pct(shape_diff)
            << (shape_diff <= 0.05 ? ", so curvature plays no measurable part under a normal push in this test."
                                   : ", so the curvature of the sphere matters in this test.");
  std::ostringstream md;
  md << "# isotouch stability\n\nHeld contact (device mass " << h0.device.mass_kg * 1e3 << " g, hand spring "
     << h0.device.hand_stiffness_n_per_m << " N/m, hand damping " << h0.device.hand_damping_n_s_per_m << " N s/m, "
     << h0.push_force_n << " N pre-load, impact at " << h0.approach_speed_m_s
     << " m/s) on a flat wall and on the top of a sphere (r = " << sphere_r * 1e3 << " mm), HRI with n = " << h0.plane_update_period
     << ". K_max is the largest stiffness for which the contact neither sustains oscillation (late oscillation "
        "energy above half the early one) nor gains energy (rendered work minus device damping loss above 1 % "
        "of the stored wall energy); log bisection. Bound: Colgate and Schenkel, K_max = 2 (b - |B|) / T.\n\n"
     << reading.str() << "\n\n";
  md << "| shape | T [ms] | b [N s/m] | B [N s/m] | bound [N/m] | K_max [N/m] | ratio | K_max with passivity controller [N/m] |\n"
     << "|---|---|---|---|---|---|---|---|\n";
  for (const Row& r : rows)
    md << "| " << r.shape << " | " << r.T * 1e3 << " | " << r.b << " | " << r.B << " | " << r.bound << " | "
       << std::setprecision(5) << r.kmax << " | " << std::setprecision(3) << r.kmax / r.bound << " | "
       << std::setprecision(5) << r.kmax_pc << (r.kmax_pc >= r.bound * 64 * 0.999 ? " (search limit)" : "") << " |\n";
  md << "\n";
  if (plotted) md << "![measured K_max against the bound](stability.png)\n\n";
  md << "## Extreme cases\n\n| case | expectation | result | detail |\n|---|---|---|---|\n";
  for (const auto& c : cases)
    md << "| " << c.name << " | " << c.expectation << " | " << (c.passed ? "pass" : "**FAIL**") << " | " << c.detail << " |\n";
  md << "| random ticks (property) | " << prop_expect << " | " << (bad == 0 ? "pass" : "**FAIL**") << " | "
     << prop << " |\n";
  write_file_atomic((fs::path(dir) / "stability.md").string(), md.str());

  log << "\nK_max / bound per servo period (flat wall, B = 0 rows):\n";
  for (double T : periods) {
    log << "  T = " << T * 1e3 << " ms:";
    for (const Row& r : rows)
      if (r.T == T && r.shape == "wall" && r.B == 0) log << "  b=" << r.b << ": " << std::setprecision(3) << r.kmax / r.bound;
    log << "\n";
  }
  log << "wrote " << dir << "/stability.csv, extreme_cases.csv, stability.md" << (plotted ? ", stability.png" : "") << "\n";
  return all ? 0 : 4;
}

}  // namespace isotouch::bench
