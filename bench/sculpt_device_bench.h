// sculpt_device_bench.h - `isotouch bench sculpt-device`: isotouch-sculpt --bench driven by
// the mouse and by a device, on the same scenes in the same run, to find what a device
// costs the frames. Per scene: (a) the mouse probe, with an isotouch-devemu process running
// beside it that no host connects to (its 1 kHz clock and physics still run: the machine
// carries what (b) carries, less the link); (b) --haptic emu:SOCKET against isotouch-devemu
// --rate 1000 --sine-mm 5; (c) --haptic playback:REC, the mouse run's own recording played
// back (the same HIP path as (a), a device with no threads), with the idle emulator running.
// Each mode runs at least 3 times, and again until it has at least 20,000 servo ticks.
// Printed: frame medians (all frames, frames drawn whole, frames reusing the picture), the
// ratios device / mouse with verdicts (<= 1.10), the emulator's and the app's CPU use, the
// servo's misses against the mouse's (at most ref + 3 sqrt(ref), ref scaled to the same
// tick count), the load average before and after.
#pragma once
#include <iosfwd>
#include <string>
#include <vector>

namespace isotouch::bench {

struct SculptDeviceOptions {
  std::vector<std::string> scenes{"scenes/head.json", "scenes/chest.json"};
  int width = 1024;             ///< the window's width [pixels]; its height is 3/4 of it
  long min_ticks = 20000;       ///< servo ticks each mode gathers at least (runs repeated)
  int min_runs = 3;             ///< runs per mode at least (31 frames drawn whole a run: one run's median is noisy)
  int max_runs = 12;            ///< runs per mode at most (min_runs wins): a mouse run of the head ticks about 2,000
  std::string sculpt_exe;       ///< isotouch-sculpt (default: beside this executable)
  std::string devemu_exe;       ///< isotouch-devemu (default: beside this executable)
  std::string device;           ///< Vulkan device (substring), passed on
};

/// Whether `missed` misses are no more than the reference `ref_missed` allows: at most
/// ref + 3 sqrt(ref), with ref = ref_missed scaled from `ref_ticks` to `ticks` ticks
/// (false when either has fewer than kMinVerdictTicks ticks).
bool misses_within(long missed, long ticks, long ref_missed, long ref_ticks);
/// Servo ticks each side needs before misses_within can pass.
inline constexpr long kMinVerdictTicks = 20000;

/// "device / mouse = R: <= 1.10 PASS|FAIL" for two medians [ms] (FAIL when either is not
/// finite or positive).
std::string ratio_verdict(double device_ms, double mouse_ms, double limit = 1.10);

/// Runs the bench; prints the report to `out`, progress to `progress`.
/// @return 0 when every run completed (whether or not a verdict passed), 1 otherwise.
int run_bench_sculpt_device(const SculptDeviceOptions& o, std::ostream& out, std::ostream& progress);

}  // namespace isotouch::bench
