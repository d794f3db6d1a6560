// bench_cmd.cpp - `isotouch bench SUBCOMMAND`: the options of each benchmark; the
// benchmarks themselves are bench/.
#include "isotouch/apps/bench_cmd.h"

#include <iostream>
#include <memory>

#include "isotouch/bench/bench_device.h"
#include "isotouch/bench/bench_serve.h"
#include "isotouch/bench/bench_edit.h"
#include "isotouch/bench/bench_engine.h"
#include "isotouch/apps/cli_checks.h"
#include "isotouch/bench/render_bench.h"
#include "isotouch/bench/sculpt_big_bench.h"
#include "isotouch/bench/sculpt_device_bench.h"
#include "isotouch/bench/servo_bench.h"

namespace isotouch::app {
namespace {

Subcommand add_bench_servo_rt_command(CLI::App& bench) {
  auto o = std::make_shared<bench::ServoRtOptions>();
  auto* rt = bench.add_subcommand(
      "servo-rt", "Real-time servo thread at 1, 4 and 10 kHz while the engine thread publishes: p50/p99/p99.9 "
                  "of the period error and missed deadlines");
  rt->add_option("--seconds", o->seconds, "Seconds per rate")->capture_default_str()->check(positive_number());
  rt->add_flag("--fifo,!--no-fifo", o->sched_fifo,
               "SCHED_FIFO for the servo thread (default on; needs CAP_SYS_NICE, refused -> a note)");
  rt->add_flag("--pin,!--no-pin", o->pin_cpu, "Pin the servo thread (default: the last CPU, only under SCHED_FIFO)");
  rt->add_flag("--mlock,!--no-mlock", o->lock_memory, "lock the servo thread's memory (stack, buffers) and prefault it before the loop (default on)");
  rt->add_option("--cpu", o->cpu, "Pin to this CPU (default: the last one)");
  rt->add_option("--csv", o->out_csv, "Also write the table to this CSV file");
  rt->add_option("--busy", o->busy_threads,
                 "Threads spinning in user space meanwhile (default scheduling, no syscalls): the servo's floor "
                 "when every CPU is busy with work that cannot hold a CPU against SCHED_FIFO")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  return {rt, [o](const std::string& device) {
            bench::ServoRtOptions opt = *o;
            opt.device = device;
            return bench::run_bench_servo_rt(opt, std::cout);
          }};
}

Subcommand add_bench_table1_command(CLI::App& bench) {
  auto o = std::make_shared<bench::Table1Options>();
  auto* t1 = bench.add_subcommand(
      "table1", "The paper's Table 1 again: time per servo loop and servo rate of HRI (n = 5), Avila-Sobierajski "
                "and Blezek-Robb on sphere, knot, head and lung, next to the paper's figures");
  t1->add_option("--repetitions", o->repetitions, "Timed replays per stroke (median)")
      ->capture_default_str()
      ->check(positive_number());
  t1->add_option("--csv", o->out_csv, "Also write the table to this CSV file");
  t1->add_flag("!--no-realtime", o->realtime,
               "Time the replays under the default scheduler, unpinned (default: SCHED_FIFO on one CPU, as the "
               "servo thread runs, where the system allows it)");
  return {t1, [o](const std::string& device) {
            bench::Table1Options opt = *o;
            opt.device = device;
            return bench::run_bench_table1(opt, std::cout);
          }};
}

constexpr const char* kColumnsHelp = R"(
Cases: head CT (headsq 64x64x93) at 1150 and 500, chest CT (lungdx 256x256x64) at -500
and +250, a 256^3 noisy sphere (signed distance in mm to a sphere of radius 96 voxels,
1 mm spacing, plus uniform noise in [-1, 1) mm; tau 0), all inside above. Dense list:
gaussian(1 mm) + gradient + brick_minmax(1); sparse list: gaussian(1 mm) + gradient.

Dense table, one row per pass, then the sum of the passes and the end-to-end wall time:
  min bytes      bytes the pass must read + write at least: gaussian/closing 8 B/voxel,
                 gradient 20 B/voxel (4 in, 16 out), brick_minmax 4 B/voxel + 8 B/brick
  dense GPU      PassChain (Vulkan) device time per pass [ms], median (timestamps)
  dense CPU      run_chain_cpu, one thread, wall time per pass [ms], median
  GPU / CPU      dense GPU ms / dense CPU ms
  GB/s           min bytes / time;  / memcpy: that over this machine's memcpy GB/s
                 (std::memcpy of 256 MiB, best of 5, read + write counted)
Sparse table, one row per isovalue:
  bricks, candidates, active   8^3 bricks in all, computed, published with samples
  active %       100 active / bricks
  sparse GPU     SparseChain::run total_ms (wall, all host work), median [ms], default
                 strategy: x4 passes on work lists of the candidate bricks' quads
  dense strategy the same chain running the dense x4 passes over the whole volume
  per-brick      the same chain on the per-brick shared-memory kernel
  sparse CPU     run_sparse_cpu total_ms, median [ms]
  dense GPU/CPU  end-to-end wall of the dense chain (same repetitions)
  ratios         sparse GPU / dense CPU (the must-show), sparse CPU / dense CPU,
                 sparse GPU / dense GPU
  GPU vs CPU     whether both sparse engines found the same bricks and bytes
Stages: the sparse engines' own per-stage times.
Bytes: published snapshot bytes per sample format (fp32, fp16, unorm16) against the dense
  fp32 snapshot (16 B per voxel), and the percentage.
512^3: a 512^3 noisy sphere through the sparse GPU chain (CPU reference if the GPU one is
  not available) in a child process: step time, setup, peak RSS from wait4 (ru_maxrss),
  the child's own VmHWM, snapshot bytes; then the split from the volume to the first servo
  tick: making the volume, context + chain, the chain's stages, the hand-over to the servo
  (servo::TripleBuffer), the first HRI tick, and the median of the next 999 ticks.
Verdicts: computed from the measured figures: chest -500 sparse GPU / dense CPU <= 1/3;
  chest dense GPU chain / fastest peer chain <= 1/3 and / memcpy of its bytes <= 5 (with
  the device's own copy floor, copy_x4, in the same units beside it);
  chest -500 sparse GPU / fastest peer chain <= 1/5; head sparse GPU / sparse CPU <= 1 and
  / dense CPU chain <= 1; chest +250 smallest snapshot / dense fp32 <= 0.15; 512^3 ran,
  peak RSS <= MemTotal.
Progress goes to stderr, the report (markdown) to stdout.
)";

Subcommand add_bench_engine_command(CLI::App& bench) {
  auto opt = std::make_shared<bench::BenchEngineOptions>();
  auto big_child = std::make_shared<int>(0);
  Subcommand s;
  s.app = bench.add_subcommand("engine",
                               "Engine passes dense and sparse, GPU and one-thread CPU reference, on the head CT, the "
                               "chest CT and a 256^3 synthetic volume: times, bricks active, snapshot bytes, bandwidth "
                               "against memcpy, ratios, verdicts; a 512^3 volume end to end (time, peak memory)");
  s.app->add_option("--repetitions", opt->repetitions, "Timed repetitions per figure (median)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  s.app->add_flag("--quick", opt->quick, "One repetition and no 512^3 step (unless --big): for tests");
  s.app->add_flag("--big", opt->big, "Run the 512^3 step even with --quick");
  s.app->add_flag("--closing", opt->with_closing, "Also benchmark the list with closing(radius 1 mm)");
  s.app->add_flag("--no-peers", [opt](std::int64_t) { opt->peers = false; },
                  "Do not time the peers (ITK, OpenVDB) beside the engine");
  s.app->add_option("--big-dim", opt->big_dim, "Edge of the end-to-end volume [voxels]")
      ->capture_default_str()
      ->check(CLI::Range(8, 1024));
  s.app->add_option("--cases", opt->cases, "Only these cases: head chest sphere256 (default: all)")
      ->check(CLI::IsMember({"head", "chest", "sphere256"}));
  s.app->add_option("--csv", opt->out_csv, "Also write every figure to this CSV file (long form)");
  s.app->add_option("--big-child", *big_child, "internal: run the end-to-end step in this process")->group("");
  s.app->footer(kColumnsHelp);
  s.run = [opt, big_child](const std::string& device) {
    if (*big_child > 0) return bench::run_big_child(*big_child, device, std::cout, std::cerr);
    opt->device = device;
    return bench::run_bench_engine(*opt, std::cout, std::cerr);
  };
  return s;
}

constexpr const char* kEditHelp = R"(
What it measures, in one process on the scene's volume (default scenes/chest.json: its
isovalue, inside, passes and sample format):
  latency     carve and add brushes (radius 2, 5, 10 mm; each point carved, then added back)
              at isosurface crossings of the first snapshot, one at a time: from the edit
              submitted (EditSession::apply: Sculptor brush, on the CPU reference up to
              Sculptor::cpu_max_bricks touched bricks, else on the Vulkan device; LiveField
              update) to the first servo tick that reads the new snapshot (the tick notes
              the version and a steady_clock time). Median, p99, max, and the parts: brush,
              update, publish-to-tick.
  floor       each latency edit again, right after the product's, by the smallest program
              doing its work (CPU brush, passes on the reached bricks, a snapshot, publish),
              against the same servo; its stages beside the product's; the brush on the
              Vulkan device alone (one submit) beside it.
  dense       the same edits with the whole volume's passes recomputed densely (GPU
              PassChain, or run_chain_cpu without a device) and published the same way;
              dense / incremental = ratio of the medians.
  sustained   back-to-back 5 mm edits for --seconds (lengthened, but with --quick, until each
              phase has 20,000 servo ticks) while the servo runs, against the servo
              with the engine idle for as long (idle, editing; --rounds times), both on a
              live session (its servo thread; its edit thread applies what the bench
              submits): edits/s, edit-to-haptics (submit to the first tick reading it),
              voxel changes/s (replayed on the CPU reference), missed deadlines, period errors.
The servo: HRI at --rate Hz on a simulated device pressed into the surface (the scene's
script, then resting), SCHED_FIFO + pinning + mlock when the system allows.
Verdicts against the targets: 5 mm median <= 0.25 ms one at a time and sustained, p99 <= 1 ms;
>= 200 edits/s; servo misses editing <= ref + 3 sqrt(ref), ref the idle misses scaled to the
editing ticks (undecided below 20,000 ticks per phase). Exit 0 whether or not a target is met; 1 when something
failed to run. Report (markdown) on stdout, progress on stderr. Timings on a shared machine
are noisy: run it when the machine is quiet and repeat.
)";

Subcommand add_bench_edit_command(CLI::App& bench) {
  auto o = std::make_shared<bench::BenchEditOptions>();
  auto* sub = bench.add_subcommand("edit", "Edit-to-haptics latency and edit rate while sculpting the chest CT");
  sub->add_option("--scene", o->scene, "Scene file (volume, isovalue, passes, samples); default scenes/chest.json");
  sub->add_flag("--quick", o->quick, "A few seconds (CI): 6 edits per radius, 1 dense edit, one 0.5 s round");
  sub->add_option("--edits", o->edits_per_radius, "Latency edits per radius (half carve, half add)")
      ->capture_default_str()
      ->check(CLI::Range(2, 100000));
  sub->add_option("--dense-edits", o->dense_edits, "Dense full-recompute edits per radius (0: none)")
      ->capture_default_str()
      ->check(CLI::Range(0, 10000));
  sub->add_option("--seconds", o->seconds, "Length of each idle and editing phase [s]")
      ->capture_default_str()
      ->check(CLI::Range(0.05, 600.0));
  sub->add_option("--rounds", o->rounds, "Idle + editing pairs")->capture_default_str()->check(CLI::Range(1, 20));
  sub->add_option("--rate", o->rate_hz, "Servo rate [Hz]")->capture_default_str()->check(CLI::Range(500.0, 10000.0));
  sub->add_option("--brushes", o->brushes, "gpu (the CPU reference without a device) or cpu")
      ->capture_default_str()
      ->check(CLI::IsMember({"gpu", "cpu"}));
  sub->add_option("--seed", o->seed, "Seed of the edit points")->capture_default_str();
  sub->add_option("--csv", o->out_csv, "Also write every figure to this CSV file (long form, atomic)");
  sub->footer(kEditHelp);
  return {sub, [o, sub](const std::string& device) {
            bench::BenchEditOptions opt = *o;
            opt.device = device;
            if (opt.quick) {
              if (sub->count("--edits") == 0) opt.edits_per_radius = 6;
              if (sub->count("--dense-edits") == 0) opt.dense_edits = 1;
              if (sub->count("--seconds") == 0) opt.seconds = 0.5;
              if (sub->count("--rounds") == 0) opt.rounds = 1;
            }
            return bench::run_bench_edit(opt, std::cout, std::cerr);
          }};
}

Subcommand add_bench_device_command(CLI::App& bench) {
  auto o = std::make_shared<bench::BenchDeviceOptions>();
  auto* sub = bench.add_subcommand(
      "device", "Report-to-force latency (p50/p99/max) and report rate at 1, 4 and 8 kHz against the device "
                "emulator over its socket, servo misses, disconnect trials (zero force within one tick) and servo stall trials (zero force "
                "with enable cleared within 3 periods)");
  sub->add_option("--seconds", o->seconds, "Seconds per rate")->capture_default_str()->check(CLI::Range(0.1, 600.0));
  sub->add_option("--trials", o->disconnect_trials, "Disconnect trials at 1 kHz")->capture_default_str()->check(CLI::Range(1, 1000));
  sub->add_option("--stall-trials", o->stall_trials, "Servo stall trials at 1 kHz (the renderer takes 100 ms once), on the emulator and on each link")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  sub->add_flag("--fifo,!--no-fifo", o->sched_fifo, "SCHED_FIFO for the servo thread (default on; refused -> a note)");
  sub->add_flag_callback("--quick", [o] { o->seconds = 0.5, o->disconnect_trials = 3; }, "0.5 s per rate and 3 trials (CI)");
  sub->add_option("--csv", o->out_csv, "Also write the rows to this CSV file");
  return {sub, [o](const std::string&) { return bench::run_bench_device(*o, std::cout); }};
}

Subcommand add_bench_serve_command(CLI::App& bench) {
  auto o = std::make_shared<bench::BenchServeOptions>();
  auto* sub = bench.add_subcommand(
      "serve", "isotouch serve on loopback: round trip from a tracker's TRANSFORM to the force TRANSFORM answering it "
               "(p50/p99/max) at 1 kHz, alone and with a large IMAGE every few seconds, and the servo's misses in both");
  sub->add_option("scene", o->scene, "Scene served (default scenes/head.json)");
  sub->add_option("--seconds", o->seconds, "Seconds per phase")->capture_default_str()->check(CLI::Range(1.0, 600.0));
  sub->add_option("--rate", o->rate_hz, "Tracker TRANSFORMs per second")->capture_default_str()->check(CLI::Range(1.0, 10000.0));
  sub->add_option("--image-size", o->image_size, "IMAGE voxels per axis")->capture_default_str()->check(CLI::Range(8, 512));
  sub->add_option("--image-every", o->image_every_s, "Seconds between IMAGEs")->capture_default_str()->check(CLI::Range(0.5, 600.0));
  sub->add_flag("--fifo,!--no-fifo", o->sched_fifo, "SCHED_FIFO for the servo thread (default on; refused -> a note)");
  return {sub, [o](const std::string& device) {
            o->device = device;
            return bench::run_bench_serve(*o, std::cout);
          }};
}

Subcommand add_bench_render_command(CLI::App& bench) {
  auto size = std::make_shared<int>(512);
  auto frames = std::make_shared<int>(9);
  Subcommand s;
  s.app = bench.add_subcommand("render",
                               "ms per frame of the ray caster on the head and chest CTs, with and without "
                               "empty-space skipping (GPU timestamps)");
  s.app->add_option("--size", *size, "Frame width and height [pixels]")->capture_default_str()->check(CLI::Range(16, 4096));
  s.app->add_option("--frames", *frames, "Timed frames per configuration (median)")->capture_default_str()->check(CLI::Range(1, 1000));
  s.run = [size, frames](const std::string& device) { return bench::run_bench_render(*size, *frames, device); };
  return s;
}

Subcommand add_bench_sculpt_big_command(CLI::App& bench) {
  auto o = std::make_shared<bench::SculptBigOptions>();
  Subcommand s;
  s.app = bench.add_subcommand(
      "sculpt-big", "isotouch-sculpt --bench on a full-resolution CT made here (the chest resampled to 512 x 512 x 600 "
                    "int16, past one single-float texel binding; and 512 x 512 x 480, within it): frames drawn whole, "
                    "sculpting frames, edit-to-pixels, memory, verdicts (33 / 50 / 100 ms)");
  s.app->add_option("--source", o->source, "Scan to resample")->capture_default_str();
  s.app->add_option("--reference", o->reference, "Also run on this scene, in the same run (\"\": not)")->capture_default_str();
  s.app->add_option("--slices", o->slices, "Slice counts, one run each")->capture_default_str()->check(CLI::Range(1, 4096));
  s.app->add_option("--iso", o->iso, "Isovalue (inside above)")->capture_default_str()->check(finite_number());
  s.app->add_option("--size", o->width, "Window width [pixels] (height 3/4 of it)")->capture_default_str()->check(CLI::Range(64, 4096));
  s.app->add_option("--sculpt", o->sculpt_exe, "isotouch-sculpt to run (default: beside this program)");
  s.app->add_option("--keep", o->keep_dir, "Keep the made volumes in this folder (default: a temporary one, removed)");
  s.run = [o](const std::string& device) {
    o->device = device;
    return bench::run_bench_sculpt_big(*o, std::cout, std::cerr);
  };
  return s;
}

Subcommand add_bench_sculpt_device_command(CLI::App& bench) {
  auto o = std::make_shared<bench::SculptDeviceOptions>();
  Subcommand s;
  s.app = bench.add_subcommand(
      "sculpt-device", "isotouch-sculpt --bench driven by the mouse (an isotouch-devemu running idle beside it), by "
                       "--haptic emu: (isotouch-devemu --sine-mm 5) and by --haptic playback: (the mouse run's recording): "
                       "frame medians, device / mouse ratios (verdict <= 1.10), the emulator's and the app's CPU use, "
                       "servo misses (<= ref + 3 sqrt(ref)), the load");
  s.app->add_option("--scenes", o->scenes, "Scenes, one set of runs each")->capture_default_str();
  s.app->add_option("--size", o->width, "Window width [pixels] (height 3/4 of it)")->capture_default_str()->check(CLI::Range(64, 4096));
  s.app->add_option("--min-ticks", o->min_ticks, "Servo ticks each mode gathers at least (runs repeated)")->capture_default_str()->check(CLI::Range(1L, 10000000L));
  s.app->add_option("--min-runs", o->min_runs, "Runs per mode at least")->capture_default_str()->check(CLI::Range(1, 100));
  s.app->add_option("--max-runs", o->max_runs, "Runs per mode at most, for the ticks (--min-runs wins)")->capture_default_str()->check(CLI::Range(1, 100));
  s.app->add_option("--sculpt", o->sculpt_exe, "isotouch-sculpt to run (default: beside this program)");
  s.app->add_option("--devemu", o->devemu_exe, "isotouch-devemu to run (default: beside this program)");
  s.run = [o](const std::string& device) {
    o->device = device;
    return bench::run_bench_sculpt_device(*o, std::cout, std::cerr);
  };
  return s;
}

}  // namespace

std::vector<Subcommand> add_bench_commands(CLI::App& cli) {
  CLI::App* bench = cli.add_subcommand("bench", "Benchmarks that print figures");
  bench->require_subcommand(1);
  return {add_bench_servo_rt_command(*bench), add_bench_table1_command(*bench), add_bench_engine_command(*bench),
          add_bench_render_command(*bench),   add_bench_edit_command(*bench),   add_bench_device_command(*bench),
          add_bench_serve_command(*bench),    add_bench_sculpt_big_command(*bench),
          add_bench_sculpt_device_command(*bench)};
}

}  // namespace isotouch::app
