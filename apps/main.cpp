// isotouch - feel the isosurface inside a volume through a point haptic device (HRI).
#include <CLI/CLI.hpp>

#include <chrono>
#include <filesystem>
#include <iomanip>
#include <iostream>

#include "cpu_gradient.h"
#include "gradient_pass.h"
#include "run_job.h"
#include "scene.h"
#include "stability_cmd.h"
#include "bench_cmd.h"
#include "report_cmd.h"
#include "volume_io.h"
#include "vk_context.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace fs = std::filesystem;
using namespace isotouch;

namespace {

std::string default_scene() {
  if (fs::exists("scenes/head.json")) return "scenes/head.json";
  return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "head.json").string();
}

int cmd_run(const std::string& scene_path, std::string out_dir, const std::string& device, bool quiet) {
  const app::Scene scene = app::load_scene(scene_path);
  if (out_dir.empty()) out_dir = (fs::path("out") / scene.name).string();
  app::RunOptions opt;
  opt.out_dir = out_dir;
  opt.device = device;
  opt.progress = !quiet;
  std::cout << "isotouch run: scene " << scene_path << " -> " << out_dir << "/\n";
  const app::RunMetrics m = app::run_scene(scene, opt, std::cout);
  const auto& hp = scene.hri;
  std::cout << std::setprecision(4)
            << "\n== isotouch summary: " << scene.name << " ==\n"
            << "  volume        " << m.volume_path << "  (" << m.dims[0] << "x" << m.dims[1] << "x" << m.dims[2] << ")\n"
            << "  isovalue      " << hp.tau << "\n"
            << "  GPU           " << m.gpu_device << ": gradient " << m.gpu_gradient_ms << " ms; CPU reference "
            << m.cpu_gradient_ms << " ms\n"
            << "  GPU vs CPU    max abs " << m.max_abs_diff << ", relative " << m.max_rel_diff << "\n"
            << "  servo         HRI, n = " << hp.plane_update_period << ", " << hp.rate_hz << " Hz, K = "
            << hp.stiffness_n_per_m << " N/m, B = " << hp.damping_n_s_per_m << " N s/m\n"
            << "  ticks         " << m.ticks << "  (tick median " << m.tick_ns_median << " ns, p99 " << m.tick_ns_p99
            << " ns, max " << m.tick_ns_max << " ns)\n"
            << "  contact       " << m.contact_ticks << " ticks, max force " << m.max_force_n << " N (limit "
            << hp.force_limit_n << " N), max penetration " << m.max_penetration_m * 1e3 << " mm\n"
            << "  surface error RMS " << m.surface_err_rms_m * 1e3 << " mm, max " << m.surface_err_max_m * 1e3 << " mm\n"
            << "  report        " << (fs::path(out_dir) / "report.md").string()
            << (m.plots_drawn ? "  (with plots)" : ("  (" + m.plot_note + ")")) << "\n";
  return 0;
}

int cmd_check(const std::string& path, const std::string& device, double slab_mib) {
  const engine::Volume vol = engine::load_volume(path);
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
  std::cout << std::setprecision(4) << "volume      " << path << " (" << vol.grid.dims[0] << "x" << vol.grid.dims[1]
            << "x" << vol.grid.dims[2] << ", " << vol.component_type << ", " << vol.reader << ")\n"
            << "device      " << (*ctx.value)->info().name << " (" << (*ctx.value)->info().type << ")\n"
            << "GPU         gradient " << gt.gradient_ms << " ms (" << (gt.gpu_timestamps ? "timestamps" : "wall")
            << ", " << gt.slabs << " slab(s)), submit-to-fence " << gt.submit_wall_ms << " ms, upload "
            << gt.upload_ms << " ms, download " << gt.download_ms << " ms\n"
            << "CPU         gradient " << cpu_ms << " ms (reference, one thread)\n"
            << "max |grad|  " << d.max_gradient_norm << " [value/m]\n"
            << "max abs     gx " << d.max_abs[0] << "  gy " << d.max_abs[1] << "  gz " << d.max_abs[2]
            << "  value " << d.max_value_abs << "\n"
            << "max rel     gx " << d.max_abs[0] / std::max(d.max_gradient_norm, 1e-300) << "  gy "
            << d.max_abs[1] / std::max(d.max_gradient_norm, 1e-300) << "  gz "
            << d.max_abs[2] / std::max(d.max_gradient_norm, 1e-300) << "  (all " << d.max_rel
            << ", relative to max |grad|)\n";
  if (d.nonfinite) std::cout << "mismatched non-finite samples: " << d.nonfinite << "\n";
  const bool ok = d.max_rel <= 1e-6;
  std::cout << (ok ? "PASS" : "FAIL") << "        tolerance 1e-6 relative\n";
  return ok ? 0 : 3;
}

int cmd_devices() {
  auto devs = engine::VulkanContext::list_devices();
  if (!devs) throw std::runtime_error("Vulkan: " + devs.error);
  for (std::size_t i = 0; i < devs.value->size(); ++i) {
    const auto& d = (*devs.value)[i];
    std::cout << i << ": " << d.name << " (" << d.type << ", " << d.driver << ")\n";
  }
  return 0;
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
      "  ISOTOUCH_DEVICE=llvmpipe isotouch run # choose the Vulkan device"};
  cli.require_subcommand(1);
  std::string device;
  cli.add_option("--device", device,
                 "Vulkan device: name substring or index (default: $ISOTOUCH_DEVICE, else the first "
                 "discrete GPU, else lavapipe)");

  auto* run = cli.add_subcommand("run", "Simulate a probe touching and stroking the isosurface of a scene; "
                                        "write trace.csv, summary.json, report.md and plots");
  std::string scene_path = default_scene(), out_dir;
  bool quiet = false;
  run->add_option("scene", scene_path, "Scene JSON file")->capture_default_str();
  run->add_option("--out,-o", out_dir, "Output folder (default: out/<scene name>)");
  run->add_flag("--quiet,-q", quiet, "No progress line");

  auto* check = cli.add_subcommand("check", "Compare the GPU gradient with the CPU reference on a volume");
  std::string volume;
  double slab_mib = 0;
  check->add_option("volume", volume, "Volume file (.mhd, .nrrd, .nhdr, .nii, .nii.gz)")->required();
  check->add_option("--max-binding-mib", slab_mib,
                    "Limit storage-buffer bindings to this size (forces z-slabs; default: device limit)")
      ->check(CLI::NonNegativeNumber);

  cli.add_subcommand("devices", "List the Vulkan devices");

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
  rt->add_option("--seconds", rt_opt.seconds, "Seconds per rate")->capture_default_str()->check(CLI::PositiveNumber);
  rt->add_flag("--fifo", rt_opt.sched_fifo, "Ask for SCHED_FIFO (needs CAP_SYS_NICE)");
  rt->add_option("--cpu", rt_opt.cpu, "Pin the servo thread to this CPU");
  rt->add_option("--csv", rt_opt.out_csv, "Also write the table to this CSV file");
  auto* t1 = bench->add_subcommand(
      "table1", "The paper's Table 1 again: time per servo loop and servo rate of HRI (n = 5), Avila-Sobierajski "
                "and Blezek-Robb on sphere, knot, head and lung, next to the paper's figures");
  app::Table1Options t1_opt;
  t1->add_option("--repetitions", t1_opt.repetitions, "Timed replays per stroke (median)")
      ->capture_default_str()->check(CLI::PositiveNumber);
  t1->add_option("--csv", t1_opt.out_csv, "Also write the table to this CSV file");

  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  try {
    if (run->parsed()) return cmd_run(scene_path, out_dir, device, quiet);
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
    if (rt->parsed()) {
      rt_opt.device = device;
      return app::run_bench_servo_rt(rt_opt, std::cout);
    }
    return cmd_devices();
  } catch (const std::exception& e) {
    std::cerr << "\nisotouch: error: " << e.what() << "\n";
    return 1;
  }
}
