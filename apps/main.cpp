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
#include "run_cmd.h"
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

  const app::Subcommand run = app::add_run_command(cli);

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
    if (run.app->parsed()) return run.run(device);
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
