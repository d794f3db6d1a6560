// isotouch - feel the isosurface inside a volume through a point haptic device (HRI).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <vector>

#include "cpu_gradient.h"
#include "vdb_io.h"
#include "gradient_pass.h"
#include "live_cmd.h"
#include "run_job.h"
#include "stop_signal.h"
#include "cli_checks.h"
#include "scene.h"
#include "stability_cmd.h"
#include "bench_cmd.h"
#include "bench_edit.h"
#include "bench_engine.h"
#include "export_cmd.h"
#include "render_cmd.h"
#include "replay_cmd.h"
#include "check_cmd.h"
#include "devices_cmd.h"
#include "bench_device.h"
#include "report_cmd.h"
#include "sim_device.h"
#include "volume_io.h"
#include "vk_context.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace fs = std::filesystem;
using namespace isotouch;

namespace {

// `isotouch run --help` footer: the scene format in short (README, "Scenes", says more).
constexpr const char* kSceneHelp = R"(
Scene file (JSON; unknown or repeated keys are errors; units are in the key names):
  {
    "name": "head",                             letters, digits, '-', '_' (default: file stem)
    "volume": {"path": "../data/ct-head-headsq/headsq_64x64x93_int16.mhd"},
                                                relative to the scene file; .mhd .mha .nrrd .nhdr .nii .nii.gz
                                                .vdb, or a DICOM series folder (one file per slice)
           or {"synthetic": "sphere", "dims": [64, 64, 64], "spacing_m": 0.001, "radius_vox": 20}
           or {"synthetic": "box" | "three-spheres" | "knot"}
    "isovalue": 1150,                           required; in the volume's units (HU for CT)
    "inside": "above",                          "above": value > isovalue is inside; "below"
    "servo":  {"stiffness_n_per_m": 800, "damping_n_s_per_m": 1.0, "plane_update_period": 5,
               "rate_hz": 1000, "force_limit_n": 3.3, "variant": "robust" | "paper", ...},
                                                optional, like every section below; see README, Scenes
    "device": {"mass_kg": 0.08, "hand_stiffness_n_per_m": 300, "hand_damping_n_s_per_m": 5, ...},
    "script": {"ray_origin_frac": [0.5, 0.5, 1.2], "ray_direction": [0, 0, -1],
               "stroke_direction": [1, 0, 0], "press_depth_m": 0.008, "stroke_length_m": 0.04, ...},
    "outputs": {"trace_csv": true, "plots": true},
    "engine": {"passes": [{"gaussian": {"sigma_mm": 1.0}}, {"closing": {"radius_mm": 1}}, "gradient"],
               "mode": "sparse" | "dense", "samples": "fp32" | "fp16" | "unorm16"},
    "edits": {"brush": {"kind": "drill", "radius_mm": 4.5, "falloff": 0.5, "force_threshold_n": 0.5,
                        "removal_per_n_s": 2, ...},  also strength, density_scale, material, empty
              "every_ticks": 10, "button": [[0.5, 4.6]], "history_limit_mib": 64,
              "write_vdb": true, "write_stl": true,
              "timeline": [{"t_s": 1.0, "kind": "carve", "at": "vhip" | [x, y, z] (mm), "duration_s": 0.2,
                            "radius_mm": 3, ...}, {"t_s": 2.0, "kind": "undo" | "redo"}]}
  }
edits (optional, needs mode "sparse"): sculpting while the servo runs. While the
button is down and the probe is in contact, the brush is applied at the VHIP every
every_ticks ticks (drill: removal grows with |F| above force_threshold_n; removal_per_n_s is
the fraction of the material-to-empty value range removed per N above it per s, the same on
every volume; "rate" gives it in value units per N s instead), one undo stroke
per press; timeline brushes fire at their time. Each edit recomputes only the bricks it can
change and publishes a new snapshot the next tick reads. Outputs add edits.csv, edits.png
(force, depth and removed volume against time), before.png / after.png, drilled.vdb and
drilled.stl. Shipped: scenes/drill-skull.json.
engine (optional): the passes that compute the published samples, in order; a pass is its
name or {"name": {parameters}}: gaussian (sigma_mm > 0), closing (radius_mm >= 0, a box),
gradient (required, after the filters), brick_minmax (halo 0..8, default 1). Only the listed
passes' pipelines and buffers are created; report.md and summary.json list what ran and what
was left out. Default: ["gradient"], mode "sparse" (only 8^3 bricks near the isosurface are
computed and published), samples "fp32" (16 B per sample; fp16 and unorm16 are 8 B and need
mode "sparse"). mode "dense" computes every voxel, for comparison.
The script casts a ray from ray_origin_frac (fractions of the volume box, each in [-2, 3])
to the first isosurface crossing, presses the hand target press_depth_m in, strokes
stroke_length_m along the surface, and lifts off. Shipped: scenes/head.json, chest.json,
chest-full.json (the chest's DICOM series at full resolution), sphere.json, knot.json,
drill-skull.json. `run --record FILE` also writes a recording that
`isotouch replay FILE` plays back, checking every force bit for bit.

Outputs in --out: trace.csv (one row per tick), summary.json, report.md, plots (gnuplot).
Points are reported in the volume's physical frame (origin + direction x spacing x index).
Exit status: 0 ok; 1 bad input (the message names the file, field and value);
4 the run had servo fault ticks; 5 (--live) the haptic device was disconnected, faulty or sent
refused reports.

The Vulkan device: --device NAME|INDEX, before or after `run`, or ISOTOUCH_DEVICE.

Example:
  isotouch run scenes/sphere.json --out /tmp/sphere --device llvmpipe
)";

std::string default_scene() {
  if (fs::exists("scenes/head.json")) return "scenes/head.json";
  return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "head.json").string();
}

int cmd_run_live(const std::string& scene_path, const std::string& device, bool quiet, const std::string& record_path,
                 const std::string& haptic) {
  const io::Scene scene = io::load_scene(scene_path);
  app::LiveOptions opt;
  opt.haptic = haptic;
  opt.run.device = device;
  opt.run.progress = !quiet;
  opt.run.record_path = record_path;
  std::cout << "isotouch run --live: scene " << scene_path << "\n";
  return app::run_live(scene, opt, std::cout);
}

int cmd_run(const std::string& scene_path, std::string out_dir, const std::string& device, bool quiet,
            const std::string& record_path) {
  const io::Scene scene = io::load_scene(scene_path);
  if (out_dir.empty()) out_dir = (fs::path("out") / scene.name).string();
  app::RunOptions opt;
  opt.out_dir = out_dir;
  opt.device = device;
  opt.progress = !quiet;
  opt.record_path = record_path;
  std::cout << "isotouch run: scene " << scene_path << " -> " << out_dir << "/\n";
  {
    const double dt = 1.0 / scene.hri.rate_hz;
    const int need = sim::min_stable_substeps(scene.device, dt);
    if (need > scene.device.substeps)
      std::cout << "device   substeps raised from " << scene.device.substeps << " to " << need
                << " per servo period so the simulated device integrates stably (mass " << scene.device.mass_kg
                << " kg, hand " << scene.device.hand_stiffness_n_per_m << " N/m and "
                << scene.device.hand_damping_n_s_per_m << " N s/m)\n";
  }
  session::install_stop_handlers();  // SIGINT/SIGTERM: stop at the next safe point, folder marked
  app::RunMetrics m;
  try {
    m = app::run_scene(scene, opt, std::cout);
  } catch (const session::Interrupted& e) {
    std::cerr << "\nisotouch run: " << e.what() << "; " << (fs::path(out_dir) / "summary.json").string()
              << " says \"status\": \"interrupted\" and lists the files that were finished\n";
    return 128 + e.signal;
  }
  const auto& hp = scene.hri;
  const double limit = hp.force_limit_n;
  std::cout << std::setprecision(4)
            << "\n== isotouch summary: " << scene.name << " ==\n"
            << "  volume        " << m.volume_path << "  (" << m.dims[0] << "x" << m.dims[1] << "x" << m.dims[2]
            << (m.orientation.empty() ? std::string() : ", orientation " + m.orientation) << ")\n"
            << "  isovalue      " << hp.tau << "\n"
            << "  GPU           " << m.gpu_device << ": gradient " << m.gpu_gradient_ms << " ms; CPU reference "
            << m.cpu_gradient_ms << " ms\n"
            << "  GPU vs CPU    max abs " << m.max_abs_diff << ", relative " << m.max_rel_diff << "\n"
            << "  servo         HRI, n = " << hp.plane_update_period << ", " << hp.rate_hz << " Hz, K = "
            << hp.stiffness_n_per_m << " N/m, B = " << hp.damping_n_s_per_m << " N s/m\n"
            << "  ticks         " << m.ticks << "  (tick median " << m.tick_ns_median << " ns, p99 " << m.tick_ns_p99
            << " ns, max " << m.tick_ns_max << " ns)\n"
            << "  contact       " << m.contact_ticks << " ticks, max force " << m.max_force_n << " N (limit "
            << limit << " N), max penetration " << m.max_penetration_m * 1e3 << " mm\n"
            << "  force step    max " << m.max_force_step_n << " N between two contact ticks ("
            << (limit > 0 ? 100.0 * m.max_force_step_n / limit : 0.0) << " % of the limit, at t = "
            << m.max_force_step_t_s << " s)\n"
            << "  faults        " << m.fault_ticks << " of " << m.ticks << " ticks\n"
            << "  surface error RMS " << m.surface_err_rms_m * 1e3 << " mm, max " << m.surface_err_max_m * 1e3 << " mm\n"
            << "  report        " << (fs::path(out_dir) / "report.md").string()
            << (m.plots_drawn ? "  (with plots)" : ("  (" + m.plot_note + ")")) << "\n";
  if (m.fault_ticks > 0) {
    std::cerr << "\nisotouch: error: " << m.fault_ticks << " of " << m.ticks
              << " servo ticks were faults (non-finite input or state; zero force sent): the run is not "
                 "trustworthy. See "
              << (fs::path(out_dir) / "trace.csv").string() << " (column fault).\n";
    return 4;
  }
  return 0;
}

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

int cmd_check(const std::string& path, const std::string& device, double slab_mib) {
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
  std::cout << std::setprecision(4) << "volume      " << path << " (" << vol.grid.dims[0] << "x" << vol.grid.dims[1]
            << "x" << vol.grid.dims[2] << ", " << vol.component_type << ", " << vol.reader << ")\n"
            << "spacing     " << vol.grid.spacing_m.x * 1e3 << " x " << vol.grid.spacing_m.y * 1e3 << " x "
            << vol.grid.spacing_m.z * 1e3 << " mm\n"
            << "orientation " << vol.orientation() << " (index axes x, y, z point toward; physical frame LPS)"
            << (vol.direction_is_identity ? ", direction identity" : "") << "\n";
  if (!vol.direction_is_identity)
    std::cout << "direction   [" << D[0] << " " << D[1] << " " << D[2] << "; " << D[3] << " " << D[4] << " " << D[5]
              << "; " << D[6] << " " << D[7] << " " << D[8] << "] (columns: index axes in LPS)\n";
  std::cout << "corners     voxel (0,0,0) at (" << vol.grid.origin_m.x * 1e3 << ", " << vol.grid.origin_m.y * 1e3
            << ", " << vol.grid.origin_m.z * 1e3 << ") mm, last voxel at (" << far.x * 1e3 << ", " << far.y * 1e3
            << ", " << far.z * 1e3 << ") mm (physical)\n"
            << "values      ";
  if (vol.finite_voxels > 0)
    std::cout << "[" << vol.min_value << ", " << vol.max_value << "]";
  else
    std::cout << "no finite voxel";
  std::cout << "; NaN voxels " << vol.nan_voxels << ", Inf voxels " << vol.inf_voxels << " of " << vol.voxels.size()
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
  if (d.nonfinite) std::cout << "mismatched non-finite samples: " << d.nonfinite << "\n";
  if (gh.nonfinite == 0 && gh.max_norm == 0.0)
    std::cout << "note        the gradient is zero everywhere: a constant volume has no isosurface to feel\n";
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
    std::cout << "PASS        tolerance 1e-6 relative\n";
    return 0;
  }
  std::cout << "FAIL       ";
  for (const auto& w : why) std::cout << " " << w << ";";
  std::cout << "\n";
  return 3;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App cli{
      "isotouch: feel the isosurface inside a volume (CT, MR, sculpted) through a point haptic\n"
      "device with the HRI servo (intermediate virtual plane), from samples a Vulkan compute\n"
      "shader precomputed.\n\n"
      "Examples:\n"
      "  isotouch run                          # default scene scenes/head.json -> out/head/\n"
      "  isotouch run scenes/chest.json --out /tmp/chest\n"
      "  isotouch check data/ct-tooth/tooth.nhdr\n"
      "  isotouch check data/ct-chest-lungdx-a0001/dicom-5mm   # a DICOM series folder\n"
      "  ISOTOUCH_DEVICE=llvmpipe isotouch run # choose the Vulkan device"};
  cli.require_subcommand(1);
  // Options of the main command (--device) are accepted after the subcommand too:
  // `isotouch run scenes/x.json --device llvmpipe`. Inherited by every subcommand.
  cli.fallthrough();
  std::string device;
  cli.add_option("--device", device,
                 "Vulkan device: name substring or index (default: $ISOTOUCH_DEVICE, else the first "
                 "discrete GPU, else lavapipe); before or after the subcommand");

  auto* run = cli.add_subcommand("run", "Simulate a probe touching and stroking the isosurface of a scene; "
                                        "write trace.csv, summary.json, report.md and plots");
  std::string scene_path = default_scene(), out_dir;
  bool quiet = false;
  run->add_option("scene", scene_path, "Scene JSON file")->capture_default_str();
  run->add_option("--out,-o", out_dir, "Output folder (default: out/<scene name>)");
  run->add_flag("--quiet,-q", quiet, "No progress line");
  std::string record_path;
  run->add_option("--record", record_path,
                  "Also write every device input, button and edit with its time to FILE (replay it with "
                  "`isotouch replay FILE`)");
  bool live = false;
  run->add_flag("--live", live,
                "Run the scene in real time on the live session's threads: the servo thread (SCHED_FIFO when "
                "allowed) drives the simulated device, an edit thread applies the button drill and the timeline; "
                "with --record FILE the recording is streamed while it runs (FILE.part until it stops; a killed "
                "run leaves FILE.part, replayable up to its last chunk)");
  std::string haptic = "sim";
  run->add_option("--haptic", haptic,
                  "With --live: the haptic device, KIND[:ARGS]: sim (the scene's simulated device, default), null, "
                  "playback:FILE (trace.csv or .rec), hid:VID:PID[:SERIAL], hid:/dev/hidrawN, emu:SOCKET "
                  "(isotouch-devemu); `isotouch devices` lists the HID devices")
      ->capture_default_str();
  std::string hand_path;
  run->add_option("--hand-path", hand_path,
                  "Write the scene's scripted hand (device frame, t_s,x_m,y_m,z_m every ms) to FILE for "
                  "isotouch-devemu --path, and exit");
  run->footer(kSceneHelp);

  auto* check = cli.add_subcommand(
      "check", "Compare the GPU gradient with the CPU reference on a volume; with --all, every engine pass "
               "(Gaussian, closing, gradient, brick min/max) against its CPU reference and OpenVDB");
  std::string volume;
  double slab_mib = 0;
  app::CheckAllOptions check_all;
  bool check_all_flag = false;
  check->add_option("volume", volume,
                    "Volume file (.mhd, .mha, .nrrd, .nhdr, .nii, .nii.gz, .vdb) or DICOM series folder (its slices; "
                    "with several series, the one with the most slices); not with --scene");
  check->add_flag("--all", check_all_flag,
                  "Every pass (gaussian 1 mm, closing 1 mm, gradient, brick_minmax) on the GPU against its "
                  "one-thread CPU reference, the gradient against OpenVDB too: a table of max abs/relative "
                  "difference, ULP max/p99, non-identical and NaN/Inf counts, GPU and CPU time. Exit 3 on "
                  "disagreement (bit identity on a CPU device such as lavapipe, 64 ULP elsewhere)");
  check->add_option("--scene", check_all.scene_path,
                    "With --all: the scene's volume and isovalue (passes: the default list)");
  check->add_flag("--validation", check_all.validation,
                  "With --all: Vulkan validation layer on (also ISOTOUCH_VALIDATION=1); any message fails the check");
  // Debug only, hidden: proves the comparison can fail (moves one CPU Gaussian value by 1000 ULP).
  check->add_flag("--inject-mismatch", check_all.inject_mismatch)->group("");
  check->add_option("--max-binding-mib", slab_mib,
                    "Limit storage-buffer bindings to this size (forces z-slabs; default: device limit)")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            double v = 0;
            std::size_t used = 0;
            try {
              v = std::stod(text, &used);
            } catch (const std::exception&) {
              used = 0;
            }
            if (used != text.size() || !(v > 0.0 && v <= 1048576.0))
              return "must be a number of MiB in (0, 1048576], got " + text;
            return {};
          },
          "MiB in (0, 1048576]"));

  cli.add_subcommand("devices", "List the Vulkan devices and the HID devices (VID:PID, serial, path, known protocol)");

  auto* stab = cli.add_subcommand(
      "stability", "Measure the largest stable stiffness K_max against Colgate-Schenkel's bound 2(b-|B|)/T "
                   "(T = 1, 0.25, 0.1 ms; several b), with and without the passivity controller, and run the "
                   "extreme cases; write stability.csv, extreme_cases.csv, stability.png, stability.md");
  std::string stab_out = "out/stability";
  bool stab_quick = false;
  stab->add_option("--out,-o", stab_out, "Output folder")->capture_default_str();
  stab->add_flag("--quick", stab_quick, "Shorter runs and coarser search (for tests)");

  auto* report = cli.add_subcommand(
      "report", "Error against run time: sweep algorithm (HRI, Avila-Sobierajski, Blezek-Robb) x n x options x "
                "scene along the same strokes; write error_vs_time.csv/.png/.md");
  app::ReportOptions rep;
  report->add_option("--scenes", rep.scenes,
                     "Scenes: sphere box three-spheres knot head chest, or scene JSON files")
      ->capture_default_str();
  report->add_option("--out,-o", rep.out_dir, "Output folder")->capture_default_str();

  auto* bench = cli.add_subcommand("bench", "Benchmarks that print figures");
  bench->require_subcommand(1);
  auto* rt = bench->add_subcommand(
      "servo-rt", "Real-time servo thread at 1, 4 and 10 kHz while the engine thread publishes: p50/p99/p99.9 "
                  "of the period error and missed deadlines");
  app::ServoRtOptions rt_opt;
  rt->add_option("--seconds", rt_opt.seconds, "Seconds per rate")->capture_default_str()->check(app::positive_number());
  rt->add_flag("--fifo,!--no-fifo", rt_opt.sched_fifo,
               "SCHED_FIFO for the servo thread (default on; needs CAP_SYS_NICE, refused -> a note)");
  rt->add_flag("--pin,!--no-pin", rt_opt.pin_cpu,
               "Pin the servo thread (default: the last CPU, only under SCHED_FIFO)");
  rt->add_flag("--mlock,!--no-mlock", rt_opt.lock_memory, "mlockall and prefault before the loop (default on)");
  rt->add_option("--cpu", rt_opt.cpu, "Pin to this CPU (default: the last one)");
  rt->add_option("--csv", rt_opt.out_csv, "Also write the table to this CSV file");
  auto* t1 = bench->add_subcommand(
      "table1", "The paper's Table 1 again: time per servo loop and servo rate of HRI (n = 5), Avila-Sobierajski "
                "and Blezek-Robb on sphere, knot, head and lung, next to the paper's figures");
  app::Table1Options t1_opt;
  t1->add_option("--repetitions", t1_opt.repetitions, "Timed replays per stroke (median)")
      ->capture_default_str()->check(app::positive_number());
  t1->add_option("--csv", t1_opt.out_csv, "Also write the table to this CSV file");
  // Command modules that keep their options to themselves (apps/subcommand.h).
  const std::vector<app::Subcommand> modules = {app::add_render_command(cli), app::add_export_command(cli),
                                                app::add_bench_engine_command(*bench),
                                                app::add_bench_render_command(*bench),
                                                app::add_bench_edit_command(*bench), app::add_replay_command(cli),
                                                app::add_bench_device_command(*bench)};

  try {
    cli.parse(argc, argv);
    if (run->parsed() && !live && run->count("--haptic") > 0)
      throw CLI::ValidationError("--haptic needs --live (a simulated run drives the scene's simulated device)");
    if (check->parsed()) {
      if (!check_all_flag && (!check_all.scene_path.empty() || check_all.validation || check_all.inject_mismatch))
        throw CLI::ValidationError("--scene, --validation and --inject-mismatch need --all");
      if (!check_all_flag && volume.empty()) throw CLI::RequiredError("volume");
      if (check_all_flag && volume.empty() == check_all.scene_path.empty())
        throw CLI::ValidationError("check --all: give a VOLUME file or --scene SCENE, one of them");
    }
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  try {
    if (run->parsed() && !hand_path.empty()) return app::write_hand_path(io::load_scene(scene_path), hand_path, std::cout);
    if (run->parsed() && live) return cmd_run_live(scene_path, device, quiet, record_path, haptic);
    if (run->parsed()) return cmd_run(scene_path, out_dir, device, quiet, record_path);
    if (check->parsed() && check_all_flag) {
      check_all.volume_path = volume;
      check_all.device = device;
      check_all.max_binding_mib = slab_mib;
      return app::run_check_all(check_all, std::cout);
    }
    if (check->parsed()) return cmd_check(volume, device, slab_mib);
    if (stab->parsed()) return app::run_stability(stab_out, stab_quick, std::cout);
    if (report->parsed()) {
      rep.device = device;
      return app::run_report(rep, std::cout);
    }
    if (t1->parsed()) {
      t1_opt.device = device;
      return app::run_bench_table1(t1_opt, std::cout);
    }
    for (const app::Subcommand& m : modules)
      if (m.app->parsed()) return m.run(device);
    if (rt->parsed()) {
      rt_opt.device = device;
      return app::run_bench_servo_rt(rt_opt, std::cout);
    }
    return app::run_devices(std::cout);
  } catch (const std::exception& e) {
    std::cerr << "\nisotouch: error: " << e.what() << "\n";
    return 1;
  }
}
