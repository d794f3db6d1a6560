// device_emulator.h - the firmware side of isotouch protocol v1, simulated: a point mass
// pulled by the operator's hand (sim::SimDevice) on its own clock, serving one host at a
// time over a Unix-domain SOCK_SEQPACKET socket, with injectable faults. isotouch-devemu is
// this class behind a command line; tests and `bench device` run it on a thread.
#pragma once
#include "isotouch/sim/servo_names.h"
#include <array>
#include <atomic>
#include <cstdint>
#include <mutex>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "isotouch/servo/device_io.h"
#include "isotouch/servo/hid_report.h"
#include "isotouch/sim/sim_device.h"

namespace isotouch::sim {

/// Faults, each applied to every input report with its probability, or at a time [s of the
/// emulator's clock since run() began].
struct EmuFaults {
  double drop = 0;        ///< probability a report is not sent
  double duplicate = 0;   ///< probability a report is sent twice
  double reorder = 0;     ///< probability a report is held back and sent after the next
  double garbage = 0;     ///< probability random bytes are sent instead
  double delay = 0;       ///< probability a report is sent delay_ms late
  double delay_ms = 5;
  double freeze_at_s = -1, freeze_for_s = 0;  ///< no reports at all in [at, at + for) (the link stays up)
  double disconnect_at_s = -1;                ///< the connection and the socket close here
  double reconnect_after_s = -1;              ///< ... and the socket listens again this much later (< 0: never)
  /// The times above [s] count from the host's first connection (none before it) rather
  /// than from the emulator's start: a host that starts slowly still meets them connected.
  bool from_first_connection = false;
  std::uint32_t seed = 1;
};

/// One row of a scripted hand path (device frame).
struct PathPoint {
  double t_s = 0;
  Vec3 p_m;
};

struct EmuConfig {
  std::string socket_path;        ///< created (a stale socket there is replaced; anything else is refused)
  double rate_hz = 1000;          ///< the device's report rate, 1 to 8 kHz [Hz]
  double seconds = 0;             ///< run this long; 0: until stop()
  SimDeviceParams device;         ///< mass, damping, hand spring (force_max_n: the actuator)
  /// The hand's target, device frame, by time since the host connected, looped; empty: hold `hold_m`.
  std::vector<PathPoint> path;
  Vec3 hold_m;                    ///< the hand's target without a path [m]
  /// Without a path: the hand moves the target up and down by this much [m] at sine_hz.
  double sine_amplitude_m = 0, sine_hz = 1;
  servo::DeviceCaps caps;         ///< sent in the feature report (workspace, limits, rate)
  EmuFaults faults;
  int fifo_priority = 0;          ///< > 0: run() asks for SCHED_FIFO (firmware-like timing); refused: ignored
  std::size_t output_log_size = 1 << 16;  ///< output reports kept in the log (the newest; preallocated)
  /// Speak the Polhem's USB reports instead of protocol v1 (servo/hid_report.h): lock-step
  /// (one 14-byte input report answers each output report, none unasked), encoder counts by
  /// the kinematics of polhem_config, currents in (applied whether calibrated or not, as the
  /// firmware does), the firmware's 0.5 s watchdog. info is the firmware's latched switch
  /// flag: set when the calibration switch closes, cleared only by a calibration command.
  /// By default the unit asks at once (the flag set from the first report) and until a
  /// command arrives its counts are off by polhem_offset_counts; polhem_power_up starts it as
  /// the firmware really starts. The command is taken as made in the unit's calibration
  /// pose: the counters read what it sets there (a host of the other configuration sets its
  /// own); it zeroes the force for its period, as the firmware does.
  bool polhem = false;
  servo::hid::polhem::Config polhem_config = servo::hid::polhem::kDefaultConfig;  ///< the unit's kinematics
  int polhem_lose_calibrations = 0;  ///< the first N calibration commands are lost (overwritten in the firmware's one-report queue)
  int polhem_offset_counts = 400;    ///< the uncalibrated counters' error on a, b, c (not polhem_power_up)
  /// Power-up as forsslund/haptikfabrikenapi firmware/main.cpp starts: info 0 (the flag
  /// starts clear: info 0 is not "calibrated"), counters 0 at the pose where it powered up
  /// (polhem_power_up_m) and counting from there. It asks for calibration (info 1) only once
  /// the handle is pressed into the calibration switch, at polhem_switch_at_s.
  bool polhem_power_up = false;
  /// With polhem_power_up: where the counters read 0 [m, device]; unset: where the handle
  /// starts. A pose servo::hid::polhem::encoders_for solves (Newton from the calibration pose:
  /// far outside the workspace it may find another branch of the v3 linkage).
  std::optional<Vec3> polhem_power_up_m;
  /// With polhem_power_up: when the hand presses the handle into the calibration switch [s of
  /// the emulator's clock since run() began, i.e. since power-up]; < 0: never. The press is an
  /// event (the hand's target does not move to the calibration pose; a command is taken as
  /// made there, as above).
  double polhem_switch_at_s = -1;
};

/// One output report as the emulator received it.
struct ReceivedOutput {
  std::int64_t t_ns = 0;      ///< CLOCK_MONOTONIC on arrival [ns]
  Vec3 force_n;               ///< the commanded force, device [N] (as sent, also when disabled)
  bool enable = false;        ///< the enable flag
  std::uint64_t answers = 0;  ///< the input sequence it answers
};

/// What the emulator measured (after run() returned, or a copy while it runs).
struct EmuStats {
  long reports_sent = 0, outputs_received = 0, outputs_refused = 0, connections = 0;
  long dropped = 0, duplicated = 0, reordered = 0, garbled = 0, delayed = 0;
  long watchdog_trips = 0;
  /// Report-to-force latency: from sending input report N to receiving the output report
  /// that answers N [us], one per answered report (the first answer of each). The Polhem
  /// (lock-step, no sequence): from sending a report to receiving the next currents command.
  std::vector<double> latency_us;
  double max_force_n = 0;          ///< largest |F| received with enable set [N]
  bool last_enable = false;        ///< the enable flag of the last output received
  double last_force_n = 0;         ///< |F| of the last output received, enable set or not [N]
  std::int64_t disconnect_ns = 0;  ///< CLOCK_MONOTONIC when the timed disconnect closed the link (0: none)
  std::int64_t start_ns = 0;       ///< CLOCK_MONOTONIC when run() began (its clock's 0 s)
  std::int64_t first_watchdog_ns = 0;  ///< CLOCK_MONOTONIC of the first watchdog trip (0: none)
  long outputs_unlogged = 0;       ///< output reports pushed out of the full log (the oldest)
  long calibrations = 0;           ///< Polhem: calibration commands received (lost ones included)
  long calibrations_lost = 0;      ///< Polhem: of those, lost (polhem_lose_calibrations)
  std::int64_t calibrated_ns = 0;  ///< Polhem: CLOCK_MONOTONIC when a calibration took (0: never)
  long switch_presses = 0;         ///< Polhem: times the calibration switch closed (polhem_switch_at_s)
  /// Polhem: current commands with a nonzero current received before any calibration command
  /// took since power-up (the firmware drives them: a force from uncalibrated counts).
  long currents_while_uncalibrated = 0;
};

/// The emulated device. run() blocks until `seconds` passed or stop() was called.
class DeviceEmulator {
 public:
  explicit DeviceEmulator(EmuConfig config);
  ~DeviceEmulator();
  /// Creates the socket (std::runtime_error naming the path if it cannot) and listens; after
  /// this returns a host can connect.
  void listen();
  /// The clock loop (calls listen() if it was not). Returns the statistics.
  EmuStats run();
  void stop() { stop_.store(true); }
  /// Connection closed and the socket removed now (from another thread: a "kill").
  EmuStats stats() const;
  /// The output reports received, oldest first (the newest output_log_size of them).
  std::vector<ReceivedOutput> output_log() const;

 private:
  struct Pending {
    std::int64_t due_ns;
    std::array<std::uint8_t, 32> bytes;
  };
  void tick(std::int64_t now, double t_s);
  /// The time the fault times are compared with [s]: `t_s`, or the time since the first
  /// connection (from_first_connection; -1 before it).
  double fault_time_s(double t_s) const;
  void serve_host(std::int64_t now);
  void wait_until(std::int64_t t);
  void send_report(std::int64_t now, double t_s);
  void polhem_output(std::int64_t now, std::span<const std::uint8_t> bytes);
  void polhem_report(std::int64_t now);
  std::array<std::int16_t, 6> polhem_counts() const;
  void log_output(std::int64_t now, const Vec3& force_n, bool enable, std::uint64_t answers);
  void transmit(const std::uint8_t* b, std::size_t n);
  void accept_host();
  void close_host();
  void close_listener();
  Vec3 hand_target(double t_s) const;
  bool chance(double p);

  EmuConfig cfg_;
  SimDevice dev_;
  int listen_fd_ = -1, host_fd_ = -1;
  std::atomic<bool> stop_{false};
  std::mt19937 rng_;
  std::uint32_t seq_ = 0;
  Vec3 force_n_;
  bool enabled_ = false;
  std::int64_t last_output_ns_ = 0;
  bool watchdog_tripped_ = false, disconnected_ = false, relistened_ = false;
  std::vector<std::int64_t> sent_ns_;  // by sequence % size
  std::vector<Pending> pending_;       // delayed or held back reports
  double clock_s_ = 0, connected_at_s_ = 0;  // the emulator's time, and when the host connected [s]
  double first_connected_at_s_ = -1;         // when the first host connected [s]; -1: none yet
  bool hold_next_ = false;
  bool polhem_owed_ = false, polhem_calibrated_ = false;  // Polhem: a report is owed; calibrated
  std::int64_t polhem_report_ns_ = 0;  // Polhem: when the report not yet answered by currents was sent (0: none)
  bool polhem_flag_ = false;     // Polhem: the firmware's latched switch flag (info)
  bool polhem_pressed_ = false;  // Polhem: polhem_switch_at_s has come
  std::array<std::int16_t, 6> polhem_set_{};              // Polhem: the counts the calibration set
  std::array<std::int16_t, 6> polhem_power_up_counts_{};  // Polhem, polhem_power_up: the true counts where it powered up
  Pending held_{};
  mutable std::mutex stats_mu_;
  EmuStats stats_;
  std::vector<ReceivedOutput> log_;  // a ring of output_log_size (stats_mu_)
  std::size_t logged_ = 0;           // reports logged in all (stats_mu_)
};

/// Reads a hand path CSV: a header line, then t_s,x_m,y_m,z_m rows (device frame), times
/// increasing. @throws std::runtime_error naming the file, line and field.
std::vector<PathPoint> load_path_csv(const std::string& path);

}  // namespace isotouch::sim
