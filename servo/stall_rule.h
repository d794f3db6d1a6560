// stall_rule.h - the device side's stall rule, one for every backend whose force is applied
// by a thread of its own (a report device's writer, a vendor SDK's device thread, the
// OpenIGTLink writer, serve's TRANSFORM reply thread): the servo thread writes a force once a
// tick into a latest-value cell; the output thread looks at it and takes the force off by
// itself once the servo has not written for the stall time.
#pragma once
#include "isotouch/servo/core_names.h"
#include <atomic>
#include <cstdint>

#include "isotouch/servo/latest_value.h"

namespace isotouch::servo {

/// What the output thread is to apply at one look.
struct StallLook {
  Vec3 force_n;                 ///< the servo's force while on, else an exact zero [N]
  bool on = false;              ///< force output on: enabled, written since, not stalled
  bool fresh = false;           ///< a write arrived since the last look
  bool stalled_now = false;     ///< this look counted a new stall (the force just went off)
  std::uint64_t new_writes = 0; ///< how many writes arrived since the last look
  std::uint64_t answers = 0;    ///< the reading's sequence the force answers (DeviceReading::sequence)
  std::int64_t last_write_ns = 0;  ///< when the newest write was made (stamped) or first seen [ns]
};

/// The rule, between one servo thread (write()), one output thread (restart(), look()) and
/// any thread (enable()). Times are CLOCK_MONOTONIC [ns] given by the caller.
///
/// Force only while enabled and the servo writes: none before the first write made after
/// enable() (off, not a stall). Once now - last write > the stall time while on, a stall is
/// counted (the counter enable() returns; the servo reads it each tick and ramps in from 0)
/// and the force is an exact zero until a write made after the servo could see that count;
/// that first write is itself stored as zero (no jump back to the force before the stall).
/// A non-finite force is stored as zero.
class StallRule {
 public:
  StallRule() = default;
  /// Servo thread: one store, no syscall. `now_ns` stamps the write (0: unstamped, the stall
  /// is then timed from when the output thread first saw it).
  void write(const Vec3& force_n, std::uint64_t answers, std::int64_t now_ns = 0);
  /// Any thread: force output on or off from now; `stall_s` <= 0 or not finite: `default_s`.
  /// `look_period_s`: how often the output thread looks (0: it polls, as good as always).
  /// Half of it is taken off the stall time (never below one period), so a stall is counted,
  /// and the force off, within stall_s + look_period_s / 2 of the last write: with the servo's
  /// 2.5 periods and an output thread at least as fast as the servo, within 3 servo periods.
  /// Returns the stall counter (any thread reads it).
  const std::atomic<std::uint64_t>* enable(bool on, double stall_s, double default_s, std::int64_t now_ns,
                                           double look_period_s = 0);
  /// Output thread: before its first look.
  void restart(std::int64_t now_ns);
  /// Output thread: read the clock first, then look (a write not seen after the clock was read
  /// was not made before it).
  StallLook look(std::int64_t now_ns);
  /// The time after which the next look counts a stall, if nothing is written [ns].
  std::int64_t stall_at_ns() const { return last_at_ + stall_ns_.load(std::memory_order_relaxed) + 1; }
  std::int64_t stall_ns() const { return stall_ns_.load(std::memory_order_relaxed); }
  std::uint64_t stalls() const { return stalls_.load(std::memory_order_acquire); }
  bool enabled() const { return enabled_.load(std::memory_order_acquire); }
  /// Any thread: force output off (the stall time kept).
  void disable() { enabled_.store(false, std::memory_order_release); }

 private:
  struct Output {
    Vec3 force_n;
    std::uint64_t answers = 0;
    std::uint64_t count = 0;    // +1 per write()
    std::uint64_t stalls = 0;   // the stall count this write was made after
    std::int64_t written_ns = 0;
  };
  LatestValue<Output> cell_;
  std::uint64_t writes_ = 0, stalls_seen_ = 0;  // servo thread
  std::atomic<bool> enabled_{false};
  std::atomic<std::int64_t> stall_ns_{2'500'000}, enabled_ns_{0};
  std::atomic<std::uint64_t> stalls_{0};
  // output thread
  std::uint64_t seen_count_ = 0;
  std::int64_t seen_at_ = 0;  // when the newest write was first seen
  std::int64_t last_at_ = 0;  // when the newest write was made (its stamp, else seen_at_)
  bool was_on_ = false;
};

}  // namespace isotouch::servo
