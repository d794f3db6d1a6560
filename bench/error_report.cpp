#include "isotouch/bench/error_report.h"


#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <set>
#include <functional>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

#include "isotouch/servo/baselines.h"
#include "isotouch/io/files.h"
#include "isotouch/servo/hri.h"
#include "isotouch/eval/sweep.h"
#include "isotouch/engine/vk_context.h"

namespace isotouch::bench {
using core::norm;
using eval::compare_to_dense;
using eval::measure;
using eval::median_ns_per_tick;
using eval::playback;
using eval::prepare_sweep_scene;
using eval::reference_params;
using eval::snapshot_variants;
using io::draw_with_gnuplot;
using io::gnuplot_quote;
using io::temp_name;
using io::write_file_atomic;
using eval::ErrorFigures;
using eval::FormatFigures;
using eval::Playback;
using eval::SnapshotVariant;
using eval::SweepScene;
using servo::BaselineParams;
using servo::HriParams;
using servo::Intersection;
using servo::NormalSource;
using servo::Renderer;
using servo::Variant;
namespace {
namespace fs = std::filesystem;
using namespace servo;

struct Config {
  std::string algorithm;
  int n = 1;
  std::string options;
  std::function<std::unique_ptr<Renderer>(const SweepScene&)> make;
};

struct Row {
  std::string scene;
  Config cfg;
  ErrorFigures e;
};

// One snapshot format on one scene: HRI along the recorded stroke on it.
struct FormatRow {
  std::string scene;
  SnapshotVariant v;  // field dropped after the run
  FormatFigures f;
  double tick_ns_mean = 0;
  double voxel_m = 1e-3;
};

HriParams hri_base(const SweepScene& s, int n) {
  HriParams p = reference_params(s);
  p.plane_update_period = n;
  p.intersection = Intersection::kLinear;
  p.normal = NormalSource::kSamples;
  return p;
}

// The HRI configuration the snapshot formats are compared with: the sweep's base (linear
// intersection, normals from the gradient samples, which is what the formats round), n = 1.
HriParams format_params(const SweepScene& s) { return hri_base(s, 1); }

BaselineParams baseline_base(const SweepScene& s) {
  BaselineParams b;
  b.tau = s.tau;
  b.inside = s.inside;
  b.stiffness_n_per_m = s.stiffness_n_per_m;
  b.damping_n_s_per_m = 0;
  b.rate_hz = s.rate_hz;
  b.force_limit_n = 1e3;
  return b;
}

struct HriOption {
  std::string name;
  std::function<void(HriParams&)> apply;
};

const std::vector<HriOption>& hri_options() {
  static const std::vector<HriOption> o = {
      {"linear/samples", [](HriParams&) {}},
      {"secant4/samples", [](HriParams& p) { p.intersection = Intersection::kSecant; p.intersection_steps = 4; }},
      {"bisect8/samples", [](HriParams& p) { p.intersection = Intersection::kBisection; p.intersection_steps = 8; }},
      {"linear/central", [](HriParams& p) { p.normal = NormalSource::kCentral; }},
      {"secant4/central", [](HriParams& p) {
         p.intersection = Intersection::kSecant;
         p.intersection_steps = 4;
         p.normal = NormalSource::kCentral;
       }},
      {"linear/samples/shading", [](HriParams& p) { p.force_shading = true; }},
      {"linear/samples/recovery20ms", [](HriParams& p) { p.recovery_time_s = 0.02; }},
      {"linear/samples/shading/recovery20ms", [](HriParams& p) {
         p.force_shading = true;
         p.recovery_time_s = 0.02;
       }},
  };
  return o;
}

std::vector<Config> configs() {
  std::vector<Config> c;
  for (int n : {1, 2, 5, 10, 20, 50})
    for (const HriOption& o : hri_options())
      c.push_back({"HRI", n, o.name, [n, apply = o.apply](const SweepScene& s) {
                     HriParams p = hri_base(s, n);
                     apply(p);
                     return std::unique_ptr<Renderer>(new HriRenderer(p));
                   }});
  // The paper's Figure 2 exactly as printed, at the same n: what the robust departures buy.
  for (int n : {1, 2, 5, 10, 20, 50})
    c.push_back({"HRI-paper", n, "linear/central", [n](const SweepScene& s) {
                   HriParams p = hri_base(s, n);
                   p.variant = Variant::kPaper;
                   return std::unique_ptr<Renderer>(new HriRenderer(p));
                 }});
  c.push_back({"Avila-Sobierajski", 1, "density-penetration", [](const SweepScene& s) {
                 return std::unique_ptr<Renderer>(new AvilaRenderer(baseline_base(s)));
               }});
  c.push_back({"Blezek-Robb", 1, "inch4/central", [](const SweepScene& s) {
                 return std::unique_ptr<Renderer>(new BlezekRenderer(baseline_base(s)));
               }});
  return c;
}

std::string g(double v, int p = 4) {
  std::ostringstream s;
  s << std::setprecision(p) << v;
  return s.str();
}

// The sliding part of a prescribed path, measured: duration, mean depth, mean speed.
struct Slide {
  double duration_s = 0, mean_depth_m = 0, mean_speed_m_s = 0;
  bool any = false;
};
Slide slide_of(const SweepScene& s) {
  Slide o;
  if (s.slide_end <= s.slide_begin + 1 || s.slide_end > s.hip.size()) return o;
  o.any = true;
  const double T = 1.0 / s.rate_hz;
  double len = 0, depth = 0;
  for (std::size_t k = s.slide_begin; k < s.slide_end; ++k) {
    if (k > s.slide_begin) len += norm(s.hip[k] - s.hip[k - 1]);
    if (s.truth) depth += s.truth->depth(s.hip[k]);
  }
  const double n = double(s.slide_end - s.slide_begin);
  o.duration_s = n * T;
  o.mean_depth_m = depth / n;
  o.mean_speed_m_s = len / ((n - 1) * T);
  return o;
}

// Mean cost of one steady_clock::now() pair on this machine [ns] (what per-tick timing adds).
double clock_pair_ns() {
  using clock = std::chrono::steady_clock;
  const int n = 200000;
  const auto t0 = clock::now();
  volatile std::int64_t sink = 0;
  for (int i = 0; i < n; ++i) {
    const auto a = clock::now();
    const auto b = clock::now();
    sink = sink + (b - a).count();
  }
  return std::chrono::duration<double, std::nano>(clock::now() - t0).count() / n;
}
std::string formats_csv(const std::vector<FormatRow>& rows) {
  std::ostringstream csv;
  csv << "scene,snapshot,bytes,build_ms,bricks_total,bricks_active,tick_ns_mean,contact_ticks,contact_ticks_dense,"
         "contact_mismatch_ticks,surface_err_rms_m,surface_err_max_m,force_diff_rms_n,force_diff_max_n,mean_force_dense_n\n"
      << std::setprecision(7);
  for (const FormatRow& r : rows)
    csv << r.scene << ',' << r.v.name << ',' << r.v.bytes << ',' << r.v.build_ms << ',' << r.v.bricks_total << ','
        << r.v.bricks_active << ',' << r.tick_ns_mean << ',' << r.f.contact_ticks << ',' << r.f.contact_ticks_dense << ','
        << r.f.contact_mismatch_ticks << ',' << r.f.surface_err_rms_m << ',' << r.f.surface_err_max_m << ','
        << r.f.force_diff_rms_n << ',' << r.f.force_diff_max_n << ',' << r.f.mean_force_dense_n << '\n';
  return csv.str();
}

// "## Compact samples": per scene what each snapshot format costs (surface and force error
// against the dense fp32 run) against what it saves (bytes, time); conclusions from the rows.
std::string formats_markdown(const std::vector<FormatRow>& rows) {
  std::ostringstream md;
  md << "## Compact samples: what they cost against what they save\n\n"
     << "HRI (n = 1, linear intersection, normals from the gradient samples) along the same recorded stroke on four "
        "snapshots of the same samples: fp32 dense (16 B per voxel), and bricked (8^3 bricks, only those near the "
        "isosurface store samples) in fp32 (16 B per sample), fp16 and unorm16 (8 B per sample; core/brick_field.h). "
        "Surface error: distance of the VHIP from the isosurface of the dense fp32 samples; force difference: "
        "|F - F(fp32 dense)| over the ticks where either run is in contact, relative to the dense run's mean contact "
        "force. Build: host time to make the snapshot from the dense samples (median of 3); tick: mean servo tick "
        "(median of 5 replays); both wall clock on this machine.\n\n"
     << "| scene | snapshot | bytes | % of dense | bricks active | build [ms] | mean tick [ns] | contact ticks "
        "(dense) | surface RMS / max [voxel] | force diff RMS / max [N] | force diff RMS [% of mean force] |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::map<std::string, std::uint64_t> dense_bytes;
  std::map<std::string, double> dense_rms;
  for (const FormatRow& r : rows)
    if (r.v.name == "fp32 dense") {
      dense_bytes[r.scene] = r.v.bytes;
      dense_rms[r.scene] = r.f.surface_err_rms_m;
    }
  auto pct_force = [](const FormatRow& r) {
    return r.f.mean_force_dense_n > 0 ? 100.0 * r.f.force_diff_rms_n / r.f.mean_force_dense_n : 0.0;
  };
  for (const FormatRow& r : rows) {
    const double pct = 100.0 * double(r.v.bytes) / double(std::max<std::uint64_t>(1, dense_bytes[r.scene]));
    md << "| " << r.scene << " | " << r.v.name << " | " << r.v.bytes << " | " << g(pct, 3) << " | "
       << (r.v.bricks_total ? std::to_string(r.v.bricks_active) + " of " + std::to_string(r.v.bricks_total) : "-")
       << " | " << g(r.v.build_ms, 3) << " | " << g(r.tick_ns_mean) << " | " << r.f.contact_ticks << " ("
       << r.f.contact_ticks_dense << ") | " << g(r.f.surface_err_rms_m / r.voxel_m, 3) << " / "
       << g(r.f.surface_err_max_m / r.voxel_m, 3) << " | " << g(r.f.force_diff_rms_n, 3) << " / "
       << g(r.f.force_diff_max_n, 3) << " | " << g(pct_force(r), 3) << " |\n";
  }
  // Conclusions per format, over the scenes: the worst cost and the least saving.
  md << "\n";
  for (const char* name : {"fp32 bricked", "fp16 bricked", "unorm16 bricked"}) {
    double worst_rms_increase = 0, worst_force_pct = 0, worst_force_n = 0, max_pct_bytes = 0, min_pct_bytes = 1e300;
    double tick_ratio_max = 0, tick_ratio_min = 1e300;
    long mismatches = 0;
    int n = 0;
    std::map<std::string, double> dense_tick;
    for (const FormatRow& r : rows)
      if (r.v.name == "fp32 dense") dense_tick[r.scene] = r.tick_ns_mean;
    for (const FormatRow& r : rows) {
      if (r.v.name != name) continue;
      ++n;
      worst_rms_increase = std::max(worst_rms_increase, (r.f.surface_err_rms_m - dense_rms[r.scene]) / r.voxel_m);
      worst_force_pct = std::max(worst_force_pct, pct_force(r));
      worst_force_n = std::max(worst_force_n, r.f.force_diff_max_n);
      const double pct = 100.0 * double(r.v.bytes) / double(std::max<std::uint64_t>(1, dense_bytes[r.scene]));
      max_pct_bytes = std::max(max_pct_bytes, pct);
      min_pct_bytes = std::min(min_pct_bytes, pct);
      if (dense_tick[r.scene] > 0) {
        tick_ratio_max = std::max(tick_ratio_max, r.tick_ns_mean / dense_tick[r.scene]);
        tick_ratio_min = std::min(tick_ratio_min, r.tick_ns_mean / dense_tick[r.scene]);
      }
      mismatches += r.f.contact_mismatch_ticks;
    }
    if (!n) continue;
    md << "- **" << name << "** (" << n << " scene" << (n > 1 ? "s" : "") << "): " << g(min_pct_bytes, 3) << " to "
       << g(max_pct_bytes, 3) << " % of the dense fp32 bytes; ";
    if (worst_force_n == 0 && mismatches == 0)
      md << "forces identical to the dense fp32 run on every tick";
    else
      md << "surface RMS at most " << g(worst_rms_increase, 3) << " voxel above the dense run's, force difference RMS "
         << "at most " << g(worst_force_pct, 3) << " % of the mean contact force (max " << g(worst_force_n, 3)
         << " N), " << mismatches << " ticks with contact on one run only";
    md << "; mean tick " << g(tick_ratio_min, 3) << " to " << g(tick_ratio_max, 3) << " x the dense run's.\n";
  }
  md << "\n";
  return md.str();
}

// Everything the report's files are made of.
struct Measured {
  std::string device;  // where the samples came from
  std::vector<Row> rows;
  std::vector<std::string> scene_names;
  std::map<std::string, std::string> descriptions;
  std::map<std::string, double> voxel;
  std::map<std::string, Slide> slides;
  std::map<std::string, HriParams> params;  // the HRI parameters every configuration starts from
  std::vector<FormatRow> formats;
};

// Compact samples: the same stroke on fp32 dense, fp32 bricked, fp16 and unorm16.
void measure_formats(const SweepScene& s, Measured& m, std::ostream& log) {
  std::vector<SnapshotVariant> vs = snapshot_variants(s);
  HriRenderer r(format_params(s));
  const Playback dense = playback(r, s, *vs.front().field);
  for (SnapshotVariant& v : vs) {
    FormatRow fr;
    fr.scene = s.name;
    fr.f = compare_to_dense(s, playback(r, s, *v.field), dense);
    fr.tick_ns_mean = median_ns_per_tick(r, s, *v.field, 1, 5);
    fr.voxel_m = s.voxel_m;
    v.field.reset();
    fr.v = std::move(v);
    m.formats.push_back(std::move(fr));
  }
  log << "  " << s.name << ": " << vs.size() << " snapshot formats\n";
}

// Every configuration on one scene's recorded stroke.
void measure_scene(const SweepScene& s, const std::vector<Config>& cfgs, Measured& m, std::ostream& log) {
  measure_formats(s, m, log);
  m.scene_names.push_back(s.name);
  m.descriptions[s.name] = s.description;
  m.voxel[s.name] = s.voxel_m;
  m.slides[s.name] = slide_of(s);
  m.params[s.name] = hri_base(s, 1);
  int done = 0;
  for (const Config& c : cfgs) {
    auto r = c.make(s);
    const Playback p = playback(*r, s);
    ErrorFigures e = measure(s, p);
    // The per-tick clock reads cost about as much as a tick: the mean comes from whole
    // replays instead (median of 5 after a warm-up); p99 stays per tick.
    e.tick_ns_mean = median_ns_per_tick(*r, s, 1, 5);
    m.rows.push_back({s.name, c, e});
    if (++done % 10 == 0 || done == int(cfgs.size()))
      log << "  " << s.name << ": " << done << "/" << cfgs.size() << " configurations\n";
  }
}

std::string rows_csv(const std::vector<Row>& rows) {
  std::ostringstream csv;
  csv << "scene,algorithm,n,options,tick_ns_mean,tick_ns_p99,surface_err_rms_m,angle_err_rms_deg,force_err_rms_n,"
         "max_force_step_n,pop_throughs\n"
      << std::setprecision(7);
  for (const Row& r : rows)
    csv << r.scene << ',' << r.cfg.algorithm << ',' << r.cfg.n << ',' << r.cfg.options << ',' << r.e.tick_ns_mean << ','
        << r.e.tick_ns_p99 << ',' << r.e.surface_err_rms_m << ',' << r.e.angle_err_rms_deg << ','
        << r.e.force_err_rms_n << ',' << r.e.max_force_step_n << ',' << r.e.pop_throughs << '\n';
  return csv.str();
}

// Work-precision plot: one panel per scene, one colour per algorithm, log axes. True when
// the picture was drawn.
bool plot_error_vs_time(const std::string& out_dir, const std::string& csv_path,
                        const std::vector<std::string>& scene_names) {
  const std::string png = fs::absolute(fs::path(out_dir) / "error_vs_time.png").string();
  const std::string data = fs::absolute(csv_path).string();
  const int cols = scene_names.size() > 3 ? 3 : int(scene_names.size());
  const int lines = int((scene_names.size() + 2) / 3);
  std::ostringstream gp;
  gp << "set datafile separator ','\nset terminal pngcairo size " << 460 * cols << "," << 400 * lines + 40
     << " font 'Sans,9'\nset termoption noenhanced\nset output " << gnuplot_quote(temp_name(png)) << "\n"
     << "set multiplot layout " << lines << "," << cols
     << " title 'Work-precision: RMS surface error of the contact point against mean servo tick time (this machine)'\n"
     << "set logscale xy\nset grid\nset key bottom left font ',8'\n"
     << "set xlabel 'mean tick [ns]'\nset ylabel 'surface error RMS [m]'\n";
  const std::pair<const char*, const char*> algos[] = {
      {"HRI", "#c0392b"}, {"HRI-paper", "#e67e22"}, {"Avila-Sobierajski", "#2471a3"}, {"Blezek-Robb", "#229954"}};
  for (const std::string& sn : scene_names) {
    gp << "set title '" << sn << "'\nplot ";
    bool first = true;
    for (const auto& [a, colour] : algos) {
      gp << (first ? "" : ", ") << gnuplot_quote(data) << " every ::1 using (strcol(1) eq '" << sn << "' && strcol(2) eq '"
         << a << "' ? $5 : 1/0):7 with points pt 7 ps 0.9 lc rgb '" << colour << "' title '" << a << "'";
      first = false;
    }
    gp << "\n";
  }
  gp << "unset multiplot\n";
  return draw_with_gnuplot((fs::path(out_dir) / "error_vs_time.gp").string(), gp.str(), {png}).empty();
}

// Servo parameters as used, per scene (grouped when equal).
std::string servo_text(const Measured& m) {
  std::map<std::string, std::vector<std::string>> groups;
  for (const std::string& sn : m.scene_names) {
    const HriParams& p = m.params.at(sn);
    const std::string key = "K = " + g(p.stiffness_n_per_m) + " N/m, B = " + g(p.damping_n_s_per_m) +
                            " N s/m, force limit " + g(p.force_limit_n) + " N, " + g(p.rate_hz) + " Hz";
    groups[key].push_back(sn);
  }
  std::string text;
  for (const auto& [key, names] : groups) {
    if (!text.empty()) text += "; ";
    text += key;
    if (groups.size() > 1) {
      text += " (";
      for (std::size_t i = 0; i < names.size(); ++i) text += (i ? ", " : "") + names[i];
      text += ")";
    }
  }
  return text;
}

void md_intro(const Measured& m, bool plotted, std::ostream& md) {
  const double clock_ns = clock_pair_ns();
  md << "# isotouch report: error against run time\n\n"
     << "Every configuration replays the same recorded stroke per scene (approach, press, stroke, lift; "
        "recorded once with the reference renderer on the simulated device). "
     << servo_text(m) << ". Errors over the ticks in contact: surface distance of the contact point (VHIP), angle of "
        "the force to the true normal, and the force against the exact god-object force on the true surface "
        "(synthetic scenes: exact shapes) or against the offline reference (CTs: HRI with n = 1, exact root along "
        "the segment, exact gradient of the trilinear field; the surface distance is the true distance to the "
        "trilinear isosurface). Tick times are wall times of Renderer::tick on this "
        "machine (CPU): the mean from whole replays (median of 5 after a warm-up), the p99 from per-tick clock "
        "reads (a pair of steady_clock reads costs " << g(clock_ns, 3) << " ns here, measured). Samples from "
     << m.device << ".\n\n";
  if (plotted) md << "![work-precision](error_vs_time.png)\n\n";
}

void md_pareto(const Measured& m, std::ostream& md) {
  md << "## Pareto front per scene (mean tick time against surface error RMS)\n\n";
  for (const std::string& sn : m.scene_names) {
    std::vector<const Row*> rs;
    for (const Row& r : m.rows)
      if (r.scene == sn) rs.push_back(&r);
    std::sort(rs.begin(), rs.end(), [](const Row* a, const Row* b) { return a->e.tick_ns_mean < b->e.tick_ns_mean; });
    const double vox = m.voxel.at(sn);
    md << "### " << sn << "\n\n" << m.descriptions.at(sn) << "\n\n"
       << "| algorithm | n | options | mean tick [ns] | surface RMS [voxel] | angle RMS [deg] | force RMS [N] | max force step [N] |\n"
       << "|---|---|---|---|---|---|---|---|\n";
    double best = 1e300;
    for (const Row* r : rs)
      if (r->e.surface_err_rms_m < best && r->e.contact_ticks > 0) {
        best = r->e.surface_err_rms_m;
        md << "| " << r->cfg.algorithm << " | " << r->cfg.n << " | " << r->cfg.options << " | " << g(r->e.tick_ns_mean)
           << " | " << g(r->e.surface_err_rms_m / vox, 3) << " | " << g(r->e.angle_err_rms_deg, 3) << " | "
           << g(r->e.force_err_rms_n, 3) << " | " << g(r->e.max_force_step_n, 3) << " |\n";
      }
    md << "\n";
  }
}

// The paper's Figure 2 as printed against the robust default, same n, same options.
void md_paper_vs_robust(const Measured& m, std::ostream& md) {
  md << "## The paper's Figure 2 as printed against the robust default (both linear/central: the paper's "
        "LinearInterpolation and central-difference SurfaceNormal)\n\n"
     << "Pop-throughs: ticks where the contact was lost while the HIP was more than half a voxel inside the "
        "object (exact shape, or the reference's penetration on the CTs).\n\n"
     << "| scene | n | surface RMS [voxel] paper / robust | max force step [N] paper / robust | pop-throughs paper / robust |\n"
     << "|---|---|---|---|---|\n";
  long pops_paper = 0, pops_robust = 0;
  double step_paper = 0, step_robust = 0, err_paper = 0, err_robust = 0;
  int pairs = 0;
  for (const std::string& sn : m.scene_names)
    for (int n : {1, 2, 5, 10, 20, 50}) {
      const Row *pa = nullptr, *ro = nullptr;
      for (const Row& r : m.rows)
        if (r.scene == sn && r.cfg.n == n && r.cfg.options == "linear/central") {
          if (r.cfg.algorithm == "HRI-paper") pa = &r;
          if (r.cfg.algorithm == "HRI") ro = &r;
        }
      if (!pa || !ro) continue;
      const double vox = m.voxel.at(sn);
      ++pairs;
      pops_paper += pa->e.pop_throughs;
      pops_robust += ro->e.pop_throughs;
      step_paper = std::max(step_paper, pa->e.max_force_step_n);
      step_robust = std::max(step_robust, ro->e.max_force_step_n);
      err_paper += pa->e.surface_err_rms_m / vox;
      err_robust += ro->e.surface_err_rms_m / vox;
      md << "| " << sn << " | " << n << " | " << g(pa->e.surface_err_rms_m / vox, 3) << " / "
         << g(ro->e.surface_err_rms_m / vox, 3) << " | " << g(pa->e.max_force_step_n, 3) << " / "
         << g(ro->e.max_force_step_n, 3) << " | " << pa->e.pop_throughs << " / " << ro->e.pop_throughs << " |\n";
    }
  if (!pairs) return;
  auto cmp = [](double a, double b, const char* what) {
    return std::string(a < b ? "fewer " : a > b ? "more " : "as many ") + what;
  };
  md << "\nOver these " << pairs << " pairs the robust default had " << pops_robust << " pop-throughs against "
     << pops_paper << " for the paper's Figure 2 (" << cmp(double(pops_robust), double(pops_paper), "pop-throughs")
     << "), a largest force step of " << g(step_robust, 3) << " N against " << g(step_paper, 3)
     << " N, and a mean surface RMS of " << g(err_robust / pairs, 3) << " voxel against " << g(err_paper / pairs, 3)
     << " voxel.\n\n";
}

// Remedies (§3.3) on the knot's concave side.
void md_knot_remedies(const Measured& m, std::ostream& md) {
  if (std::find(m.scene_names.begin(), m.scene_names.end(), "knot") == m.scene_names.end()) return;
  const Slide& sl = m.slides.at("knot");
  md << "## §3.3 remedies on the knot's concave side: largest force step between two ticks [N]\n\n";
  if (sl.any)
    md << "While the HIP slides " << g(sl.mean_depth_m * 1e3, 2) << " mm deep (mean) along the concave side of the tube ("
       << g(sl.duration_s, 3) << " s, " << g(sl.mean_speed_m_s * 1e3, 3) << " mm/s, measured on the path)";
  else
    md << "No sliding part is marked on this path; the largest step over the whole stroke";
  md << "; in brackets the largest step over the whole stroke, approach and lift-off included.\n\n"
     << "| n | none | force shading | recovery time 20 ms | both |\n|---|---|---|---|---|\n";
  for (int n : {10, 50}) {
    md << "| " << n;
    for (const char* opt : {"linear/samples", "linear/samples/shading", "linear/samples/recovery20ms",
                            "linear/samples/shading/recovery20ms"})
      for (const Row& r : m.rows)
        if (r.scene == "knot" && r.cfg.algorithm == "HRI" && r.cfg.n == n && r.cfg.options == opt)
          md << " | " << g(r.e.max_force_step_slide_n, 3) << " (" << g(r.e.max_force_step_n, 3) << ")";
    md << " |\n";
  }
  md << "\n";
}

// Sphere requirement: HRI, n = 1, refined intersection.
void md_sphere(const Measured& m, std::ostream& md) {
  for (const Row& r : m.rows)
    if (r.scene == "sphere" && r.cfg.algorithm == "HRI" && r.cfg.n == 1 &&
        (r.cfg.options == "secant4/samples" || r.cfg.options == "bisect8/samples"))
      md << "Sphere, HRI n = 1, " << r.cfg.options << ": surface error RMS "
         << g(r.e.surface_err_rms_m / m.voxel.at("sphere"), 3) << " voxel.\n\n";
}

}  // namespace

int run_report(const ReportOptions& o, std::ostream& log) {
  fs::create_directories(o.out_dir);
  engine::ContextOptions co;
  co.device = o.device;
  auto ctx = engine::VulkanContext::create(co);
  engine::VulkanContext* vk = ctx ? ctx.value->get() : nullptr;
  Measured m;
  m.device = vk ? vk->info().name : "CPU reference (no Vulkan: " + ctx.error + ")";
  log << "report: samples from " << m.device << "; " << o.scenes.size() << " scenes\n";
  const std::vector<Config> cfgs = configs();
  for (const std::string& name : o.scenes) measure_scene(prepare_sweep_scene(name, vk, log), cfgs, m, log);

  const std::string csv_path = (fs::path(o.out_dir) / "error_vs_time.csv").string();
  write_file_atomic(csv_path, rows_csv(m.rows));
  const bool plotted = plot_error_vs_time(o.out_dir, csv_path, m.scene_names);
  std::ostringstream md;
  md_intro(m, plotted, md);
  md_pareto(m, md);
  md_paper_vs_robust(m, md);
  md_knot_remedies(m, md);
  md_sphere(m, md);
  md << formats_markdown(m.formats);
  write_file_atomic((fs::path(o.out_dir) / "sample_formats.csv").string(), formats_csv(m.formats));
  md << "Files: `error_vs_time.csv` (all " << m.rows.size() << " configurations), `error_vs_time.gp`, "
     << "`sample_formats.csv` (" << m.formats.size() << " snapshot rows).\n";
  write_file_atomic((fs::path(o.out_dir) / "error_vs_time.md").string(), md.str());
  log << "wrote " << o.out_dir << "/error_vs_time.csv (" << m.rows.size() << " rows), error_vs_time.md"
      << (plotted ? ", error_vs_time.png" : "") << "\n";
  return 0;
}

}  // namespace isotouch::bench
