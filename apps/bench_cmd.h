// bench_cmd.h - `isotouch bench servo-rt`: the real-time servo thread under load.
#pragma once
#include <iosfwd>
#include <string>

namespace isotouch::app {

struct ServoRtOptions {
  double seconds = 10;     ///< per rate
  bool sched_fifo = false; ///< ask for SCHED_FIFO
  int cpu = -1;            ///< pin the servo thread
  std::string device;      ///< Vulkan device for the engine thread
  std::string out_csv;     ///< also write the table here (optional)
};

/// For 1, 4 and 10 kHz: run the servo thread for `seconds` while an engine thread keeps
/// recomputing a 64^3 sculpted sphere on the Vulkan device and publishing it; print p50,
/// p99, p99.9 and max of |period error| and the missed deadlines.
int run_bench_servo_rt(const ServoRtOptions& options, std::ostream& log);

struct Table1Options {
  int warmup = 3;          ///< replays discarded
  int repetitions = 21;    ///< replays timed; the median is reported
  std::string device;      ///< Vulkan device for the gradient pass
  std::string out_csv;     ///< also write the table here (optional)
};

/// The paper's Table 1 measured again: average time per servo loop [us] and servo rate
/// [kHz] of HRI (n = 5, linear interpolation, central-difference normal as in the paper),
/// Avila-Sobierajski and Blezek-Robb on sphere 64^3, knot 64^3, head and lung (chest CT),
/// each replaying the same recorded stroke; printed next to the paper's figures with the
/// ratios between algorithms.
int run_bench_table1(const Table1Options& options, std::ostream& log);

}  // namespace isotouch::app
