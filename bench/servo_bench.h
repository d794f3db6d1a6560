// servo_bench.h - `isotouch bench servo-rt` (the real-time servo thread under load) and
// `isotouch bench table1` (the paper's Table 1 measured again).
#pragma once
#include <iosfwd>
#include <string>
#include <vector>

namespace isotouch::bench {

/// What every benchmark prints about the machine it ran on (one helper for all of them).
/// /proc/loadavg's 1, 5 and 15 minute averages as "a, b, c", or "unknown".
std::string load_average();
/// /proc/cpuinfo's first "model name", or "unknown CPU".
std::string cpu_model();

struct ServoRtOptions {
  double seconds = 10;     ///< per rate [s]
  bool sched_fifo = true;  ///< ask for SCHED_FIFO (default; refused -> a note, runs anyway)
  bool pin_cpu = true;     ///< pin the servo thread (default)
  int cpu = -1;            ///< the CPU to pin to; -1: the last CPU the process may use
  bool lock_memory = true; ///< lock the servo thread's memory + prefault before the loop (default)
  std::string device;      ///< Vulkan device for the engine thread
  std::string out_csv;     ///< also write the table here (optional)
  /// Threads that spin in user space (default scheduling, no syscall, no memory traffic)
  /// during every case: the floor of a servo whose CPUs are busy with work that cannot
  /// hold a CPU against SCHED_FIFO (0: none).
  int busy_threads = 0;
};

/// For 1, 4 and 10 kHz: run the servo thread for `seconds` while an engine thread keeps
/// recomputing a 64^3 sculpted sphere on the Vulkan device and publishing it; print the
/// scheduling the thread got, p50, p99, p99.9 and max of |period error|, the missed
/// deadlines, the load average, and whether the 10 kHz target (p99.9 <= 20 us, at most 1
/// miss in 10,000 ticks) was met, computed from the measured figures. A last row runs
/// 10 kHz with the engine idle: what the machine alone allows (other processes, a VM's
/// stolen time).
int run_bench_servo_rt(const ServoRtOptions& options, std::ostream& log);

struct Table1Options {
  int warmup = 3;          ///< replays discarded
  /// Replays timed per algorithm; the median is reported. 101: on a loaded 2-CPU machine
  /// the worst HRI/Avila ratio varied 1.10-1.41 over three runs with 21, 1.07-1.10 with 101
  /// (about 4 s in all).
  int repetitions = 101;
  /// Time the replays as the servo thread runs: SCHED_FIFO, pinned to one CPU (where the
  /// system allows it; what it refused is printed). Without it a process woken on the same
  /// CPU (every 20 us, in a test) raised the head's HRI/Avila from 0.96-0.98 to 0.98-0.99.
  bool realtime = true;
  std::string device;      ///< Vulkan device for the gradient pass
  std::string out_csv;     ///< also write the table here (optional)
};

/// One measured row of Table 1: median time per Renderer::tick [us] over the same stroke.
struct Table1Row {
  std::string scene;
  double hri_us = 0;        ///< HRI as shipped (robust variant)
  double hri_paper_us = 0;  ///< HRI, Figure 2 exactly as printed (servo::Variant::kPaper)
  double blezek_us = 0;     ///< Blezek-Robb
  double avila_us = 0;      ///< Avila-Sobierajski
  /// HRI as shipped on the bricked snapshot of the same samples
  /// (core::bricked_input_from_dense + make_bricked_field), fp32 and fp16 samples.
  double hri_bricked_us = 0;
  double hri_fp16_us = 0;
};

/// "bricked/dense <= 1.10 on k of N scenes (worst: SCENE x.xx); fp16/dense: worst SCENE
/// x.xx", computed from `rows` (HRI tick on the bricked fp32 snapshot over the dense one);
/// rows with a non-positive or non-finite time count as not meeting the target.
std::string table1_bricked_verdict(const std::vector<Table1Row>& rows);

/// The conclusion of a measured Table 1, computed from `rows`: "HRI/Avila <= 1 on k of N
/// scenes (worst: SCENE x.xx); paper variant: j of N". Never a fixed sentence; rows with a
/// non-positive or non-finite time count as not meeting the target.
std::string table1_verdict(const std::vector<Table1Row>& rows);

/// The paper's Table 1 measured again: average time per servo loop [us] and servo rate
/// [kHz] of HRI (n = 5, linear interpolation, central-difference normal as in the paper;
/// the shipped robust variant and the paper's Figure 2 as printed), Avila-Sobierajski and
/// Blezek-Robb on sphere 64^3, knot 64^3, head and lung (chest CT), each replaying the same
/// recorded stroke, interleaved round by round so that all four see the same machine
/// state; printed next to the paper's figures with the ratios between algorithms and
/// table1_verdict(). Appended columns: the shipped HRI on the bricked fp32 and fp16
/// snapshots of the same samples (interleaved in the same rounds), their ratio to the dense
/// tick and table1_bricked_verdict(); the spherical tool's tick beside the point's; the floor
/// of an HRI tick (an update's, a contact tick's and a free tick's least work, no robust
/// rule) against Avila's tick; then the snapshot bytes per format.
int run_bench_table1(const Table1Options& options, std::ostream& log);

}  // namespace isotouch::bench
