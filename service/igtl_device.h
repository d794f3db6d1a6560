// igtl_device.h - an OpenIGTLink source as the haptic device, `--haptic igtl:HOST:PORT[:STREAM]`:
// a client of a PlusServer (its OpenHaptics device) or of any OpenIGTLink server that streams
// a tool's TRANSFORM.
//
//   reader thread: read_message -> TRANSFORM named STREAM -> the reading: its translation
//     [mm] -> device [m], in the stream's own frame (PLUS: RAS); the world map is the scene's
//   writer thread: once the servo has read a new pose, the servo's newest force goes back as
//     a TRANSFORM "Force" whose translation is the force [N] in the same frame (PLUS's
//     convention). The stall rule (servo/stall_rule.h): once the servo has not written for
//     its stall time a zero goes out at once (not with the next pose), and the servo's first
//     write after it is a zero (it ramps in). Zero, once, as soon as the stream is stale, so
//     that the peer never holds a contact force; zero at close; and a zero however the
//     process ends (servo/exit_zero.h: a stuck servo's _Exit, a second stop signal, a crash).
//
// Limits: the peer's device is not known here (PLUS drives it): caps() give the force limit
// the scene declares for links (IgtlDeviceOptions::max_force_n, default the Touch's 3.3 N) and
// no workspace: the servo's gate clamps to min(scene's force_limit_n, that) and limits the
// force's rate to it over 2 ms (servo/force_gate.h).
//
// The force loop closes over the network at the stream's rate, not the servo's: the device
// measures it when it opens and reports it as DeviceCaps::native_rate_hz, with a stale
// timeout of 3 stream periods (DeviceCaps::stale_timeout_s: at 1 kHz servo ticks between
// poses are not stale; a lost stream is stale, zero force, 3 periods after its last pose).
// Part of isotouch::igtl_device.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/service/igtl_socket.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/exit_zero.h"
#include "isotouch/servo/latest_value.h"
#include "isotouch/servo/stall_rule.h"
#include "isotouch/sim/linked_contact.h"

namespace isotouch::service {

struct IgtlDeviceOptions {
  std::string host;
  int port = 18944;
  std::string stream = "StylusToTracker";  ///< device name of the tool's TRANSFORMs
  double measure_s = 1.0;                   ///< how long opening listens to measure the stream's rate [s]
  int connect_timeout_ms = 3000;
  int receive_timeout_ms = 2000;            ///< longest silence inside a message [ms]
  /// > 0: the writer thread asks for SCHED_FIFO at this priority (below the servo's 80: it
  /// sends the servo's forces; starved, it would send an old force late and the new one
  /// right after, a step at the peer). Refused: the default scheduler.
  int fifo_priority = 0;
  /// The peer's device's peak force [N] (caps().max_force_n: the servo's gate clamps to it
  /// and limits the force's rate to it over 2 ms): PLUS drives the device, isotouch cannot
  /// ask it. The scene's device.link_max_force_n; the default is the Touch's 3.3 N.
  double max_force_n = 3.3;
};

/// A connection's last message however the process ends (servo/exit_zero.h: `zero`, sent on
/// a crash, a second stop signal or a stuck servo's _Exit), fencing every send on it
/// (Connection::set_fence), so that it never lands inside another message and nothing follows.
class ExitZeroFence final : public SendFence {
 public:
  ExitZeroFence(int fd, const std::vector<std::uint8_t>& zero) : zero_(fd, zero.data(), zero.size()) {}
  bool begin_send() override { return zero_.begin_send(); }
  void end_send() override { zero_.end_send(); }
  bool registered() const { return zero_.registered(); }

 private:
  servo::ExitZero zero_;
};

/// The calling thread takes no stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT): a link's own
/// threads, so that the handler that sends the last zero never runs inside one of its sends.
void block_stop_signals();

/// "HOST:PORT[:STREAM]" -> options. @throws std::invalid_argument naming the part and value.
IgtlDeviceOptions parse_igtl_spec(const std::string& arg);

/// What the stream's rate and delay must allow: the scene's stiffness against the bound of
/// a wall pressed through the link (sim::link_k_max: the scene's device and hand behind a
/// link at the loop's rate - the stream's, or the servo's when that is slower - holding each
/// force one period, plus round_trip_s), without and with the device end's passivity
/// controller; Colgate-Schenkel's 2 (b - |B|) / T is said beside it.
struct IgtlLoop {
  double servo_rate_hz = 1000;
  double handle_damping_n_s_per_m = 0;  ///< b: device + hand [N s/m]
  double servo_damping_n_s_per_m = 0;   ///< B [N s/m]
  double stiffness_n_per_m = 0;         ///< K [N/m]
  bool allow_unstable_stiffness = false;
  sim::SimDeviceParams device;          ///< the scene's device and hand (the simulated press's)
  double round_trip_s = 0;              ///< beyond the hold (device.link_round_trip_ms) [s]
  bool peer_passivity_control = false;  ///< the peer runs the controller (device.link_passivity_control)
};

/// The stiffness check of a link: its figures, its words and its verdict.
struct LinkStiffness {
  double loop_hz = 0;                   ///< min(stream, servo) [Hz]
  double colgate_n_per_m = 0;           ///< 2 (b - |B|) / T at loop_hz [N/m]
  sim::LinkBound bound;                 ///< simulated, without and with the controller
  double limit_n_per_m = 0;             ///< the bound that applies (with the controller when the peer runs it) [N/m]
  std::string text;                     ///< the bounds, the delay and what applies, for the description
  bool over = false;                    ///< K above limit_n_per_m
};
/// Judges `loop` at the stream's measured `rate_hz` (pure: the simulation only, 20-30 ms).
LinkStiffness judge_link_stiffness(const IgtlLoop& loop, double rate_hz);

class IgtlDevice final : public servo::HapticDeviceIO {
 public:
  /// Connects and listens for measure_s: the stream's rate.
  /// @throws std::runtime_error: no connection; fewer than 10 TRANSFORMs named STREAM
  ///         within measure_s (names what did arrive).
  explicit IgtlDevice(const IgtlDeviceOptions& o);
  ~IgtlDevice() override;  // a zero force sent, the threads joined
  IgtlDevice(const IgtlDevice&) = delete;
  IgtlDevice& operator=(const IgtlDevice&) = delete;

  /// The stream's rate measured while opening [Hz].
  double measured_rate_hz() const { return rate_hz_; }
  /// Force TRANSFORMs sent so far.
  long forces_sent() const { return sent_.load(); }
  /// Times the writer took the force off because the servo stopped writing.
  std::uint64_t stalls() const { return rule_.stalls(); }

  // Servo thread: no allocation, lock or syscall.
  core::Vec3 read_position_m() override { return read().position_m; }
  servo::DeviceReading read() override;
  void write_force_n(const core::Vec3& f) override;
  servo::DeviceCaps caps() const override;
  const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) override;

 private:
  struct Pose {
    core::Vec3 m;
    std::int64_t received_ns = 0;  // 0: none yet
    std::uint64_t sequence = 0;
  };
  void read_loop();
  void write_loop();
  void send_force(const core::Vec3& f);
  void measure(double seconds);

  IgtlDeviceOptions o_;
  std::shared_ptr<Connection> conn_;
  servo::LatestValue<Pose> pose_;
  Pose last_;  // servo thread
  servo::StallRule rule_;  // the servo's force (stamped) and the stall rule
  std::unique_ptr<ExitZeroFence> exit_zero_;  // the zero the peer gets however the process ends
  std::atomic<bool> stop_{false}, closed_{false};
  std::atomic<long> poses_{0}, sent_{0};
  std::atomic<std::int64_t> first_ns_{0}, last_ns_{0};
  std::atomic<long> others_{0};  // messages that were not the stream
  double rate_hz_ = 0;
  std::thread reader_, writer_;
};

/// Opens `arg` ("HOST:PORT[:STREAM]") and checks the loop it closes: `description` gets the
/// measured rate and the stiffness bound it implies. @throws std::invalid_argument on a bad
/// spec; std::runtime_error if it cannot be opened, or if loop.stiffness_n_per_m is above
/// the bound and loop.allow_unstable_stiffness is not set (the message says how to allow it).
/// `max_force_n`: the peer's device's peak force [N] (IgtlDeviceOptions::max_force_n).
std::unique_ptr<IgtlDevice> open_igtl_device(const std::string& arg, const IgtlLoop& loop, std::string& description,
                                             int fifo_priority = 0, double max_force_n = 3.3);

}  // namespace isotouch::service
