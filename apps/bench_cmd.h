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

}  // namespace isotouch::app
