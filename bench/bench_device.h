// bench_device.h - `isotouch bench device`: the device link measured against the emulator
// (sim/device_emulator.h over the Unix-domain socket link, protocol v1), in real time.
#pragma once
#include <cmath>
#include <iosfwd>
#include <string>
#include <vector>


namespace isotouch::bench {

struct BenchDeviceOptions {
  double seconds = 3;          ///< per rate [s]
  int disconnect_trials = 10;  ///< at 1 kHz
  int stall_trials = 3;        ///< at 1 kHz
  bool sched_fifo = true;      ///< SCHED_FIFO for the servo thread (refused: a note)
  std::string out_csv;         ///< also write the rows here (optional)
};

/// One rate's figures.
struct BenchDeviceRow {
  double rate_hz = 0;            ///< the device's report rate = the servo rate [Hz]
  double seconds = 0;            ///< measured wall time [s]
  double report_rate_hz = 0;     ///< input reports the host accepted per second [Hz]
  double p50_us = 0, p99_us = 0, max_us = 0;  ///< report-to-force latency [us]
  long answered = 0;             ///< reports whose force came back
  long ticks = 0, missed = 0;    ///< servo ticks and missed deadlines
  long stale = 0;                ///< servo ticks with a stale report
};

/// One disconnect trial: the emulator closes the link while the servo renders a force.
struct DisconnectTrial {
  long forced_ticks_after = 0;   ///< servo ticks that started after the disconnect and still sent force
  double zero_after_us = 0;      ///< from the disconnect to the start of the first zero-force tick [us]
};

/// One stall trial: the servo's renderer takes 100 ms once while the device is pushed,
/// measured on the wire (what the emulator received).
struct StallTrial {
  double zero_after_us = 0;      ///< from the last force received to the first zero with enable cleared [us] (NaN: none)
  long forced_during = 0;        ///< outputs with force and enable set received during the stall
  double resumed_n = 0;          ///< |F| of the first enabled output after the stall [N] (NaN: none)
  long watchdog_trips = 0;       ///< the device's own watchdog (the host's zero should come first)
};

/// A vendor SDK device's stall and step trials at 1 kHz, judged on what its library received
/// (the test doubles log it; a real SDK does not, and is then not judged).
struct SdkTrial {
  std::string kind;                  ///< "openhaptics", "forcedimension"
  std::string not_measured;          ///< why not ("" measured)
  double stall_zero_after_us = NAN;  ///< the renderer's stall began -> the first zero received [us]
  double stall_resumed_n = NAN;      ///< |F| of the first force after the stall's zeros [N]
  double steady_n = NAN;             ///< |F| before the stall [N]
  double step_max_rate_n_per_s = NAN;  ///< the largest |dF| / dt between two frames after a 0 -> 3 N step [N/s]
  double step_bound_n_per_s = NAN;     ///< what the gate allows over those frames (rate x (dt + one servo period) / dt)
  double rate_limit_n_per_s = NAN;     ///< the gate's rate limit [N/s]
  double step_rise_ms = NAN;           ///< from the first nonzero frame to the first at 3 N [ms]
};

/// An OpenIGTLink link on loopback against a PLUS-like peer in the same process streaming
/// poses at 1 kHz (`--haptic igtl:`, or serve's TRANSFORM stream): the relay delay the peer
/// sees (a Force's arrival after the newest pose it had sent), a 0 -> 3 N step (the rise at
/// the peer against the gate's rate) and a 100 ms renderer stall (the first zero at the peer
/// after it began).
struct IgtlRow {
  std::string kind;                ///< "igtl" or "serve stream"
  std::string not_measured;        ///< why not ("" measured)
  double stream_hz = 0;            ///< the poses' rate as the peer sent them [Hz]
  long forces = 0;                 ///< Force TRANSFORMs the peer received
  double p50_us = NAN, p99_us = NAN, max_us = NAN;  ///< relay delay [us]
  double stall_zero_after_us = NAN;  ///< the renderer's stall began -> the first zero at the peer [us]
  double step_rate_n_per_s = NAN;    ///< the step's largest rise between two Forces [N/s]
  double step_allowed_n_per_s = NAN; ///< what the gate allows over that gap (rate x (dt + one servo period) / dt)
  double step_rise_ms = NAN;         ///< from the first nonzero Force to the first at 3 N [ms]
};

/// "p99 report-to-force at 1 kHz = X us: target <= 1000 us met|NOT met", "zero force
/// within one tick of a disconnect in k of N trials: met|NOT met" and "zero force with
/// enable cleared within 3 periods of a servo stall ... in k of N trials: met|NOT met",
/// from the data.
std::vector<std::string> bench_device_verdicts(const std::vector<BenchDeviceRow>& rows,
                                               const std::vector<DisconnectTrial>& trials,
                                               const std::vector<StallTrial>& stalls,
                                               const std::vector<SdkTrial>& sdk = {},
                                               const std::vector<IgtlRow>& links = {});

/// Measures 1, 4 and 8 kHz and the disconnect trials; prints a table, the verdicts and
/// the machine. @return 0; 1 if nothing could be measured.
int run_bench_device(const BenchDeviceOptions& options, std::ostream& log);

}  // namespace isotouch::bench
