// delayed_link.h - a simulated network link between the servo and a remote device (the
// PLUS-like peer over OpenIGTLink): messages sent at a fixed link rate, each arriving after
// half the round-trip delay plus a random jitter, in order (a late message holds back the
// ones behind it, as on one TCP stream). The receiver holds the last value received
// (zero-order hold), as PLUS's own loop holds the last TRANSFORM.
#pragma once
#include <cstdint>
#include <deque>
#include <random>

#include "isotouch/core/setting_check.h"

namespace isotouch::sim {

/// Timing of one link [s]. Rates and delays are those of the sweep: 50-1000 Hz,
/// 0-20 ms round trip.
struct LinkParams {
  double rate_hz = 1000;            ///< messages per second, each direction [Hz]
  double round_trip_delay_s = 0;    ///< fixed delay there and back [s]; each way gets half
  double jitter_s = 0;              ///< each message is late by U(0, jitter_s) more [s]
  std::uint64_t seed = 1;           ///< jitter draws
  double period_s() const { return 1.0 / rate_hz; }
  /// @throws std::invalid_argument naming the field and its value unless rate_hz is finite
  /// and > 0 and the delay and the jitter are finite and >= 0.
  void validate() const {
    core::require_positive("LinkParams", "rate_hz", rate_hz, "Hz");
    core::require_non_negative("LinkParams", "round_trip_delay_s", round_trip_delay_s, "s");
    core::require_non_negative("LinkParams", "jitter_s", jitter_s, "s");
  }
};

/// One direction of the link, carrying values of type T.
template <class T>
class DelayLine {
 public:
  /// Rounding slack on arrival times [s]: far below any tick, far above double's error on
  /// times of hours.
  static constexpr double kArrivalSlackS = 1e-9;

  DelayLine(const LinkParams& p, std::uint64_t stream)
      : one_way_s_(0.5 * p.round_trip_delay_s), jitter_s_(p.jitter_s), rng_(p.seed * 2 + stream) {
    p.validate();
  }

  /// Sends `value` at time t_s [s]; it arrives at t_s + one way + jitter, or with the
  /// message sent ahead of it if that one is later (receive() takes them in order).
  void send(double t_s, const T& value) {
    double arrive = t_s + one_way_s_;
    if (jitter_s_ > 0) arrive += jitter_s_ * std::uniform_real_distribution<double>(0.0, 1.0)(rng_);
    queue_.push_back({arrive, value});
  }

  /// Takes every message that has arrived by t_s [s] into `held` (the last one wins); one
  /// due within kArrivalSlackS after t_s counts as arrived (t + one way is rounded in
  /// floating point: 0.026 + 0.005 > 0.031 would serve it a tick late).
  /// @return the number taken.
  int receive(double t_s, T& held) {
    int n = 0;
    while (!queue_.empty() && queue_.front().arrive_s <= t_s + kArrivalSlackS) {
      held = queue_.front().value;
      queue_.pop_front();
      ++n;
    }
    return n;
  }

 private:
  struct Message {
    double arrive_s;
    T value;
  };
  double one_way_s_, jitter_s_;
  std::mt19937_64 rng_;
  std::deque<Message> queue_;
};

}  // namespace isotouch::sim
