// input_phase.h - a servo tick placed just after a link's input arrives.
//
// A device behind a link (serve's TRANSFORM stream, a PLUS device loop) sends a pose and
// waits for the force that answers it. With the servo's ticks at a fixed phase to the
// stream's, a pose waits for the next tick anywhere from 0 to one servo period, fixed for a
// whole session by the two clocks' start (at 1 kHz: a round trip of 0.1 or 1.1 ms, by luck).
// ArrivalClock learns the input's period and phase from the arrival times; the servo moves
// its next deadline towards `lead` after the next arrival, at most 1/16 period a tick, only
// where the input's period is a whole number of servo periods (else the ticks could never
// stay aligned and the servo's period would wander). Following, the servo runs at the input's
// rate, within 0.5 % of its own: what the stiffness check assumed.
// An input that arrives after the tick meant for it waits a whole period and is overtaken by
// the next one (only the newest pose is answered), so the lead grows to cover how late the
// stream's arrivals run: the 99.5th percentile of the last 256 arrivals' lateness behind their
// predicted time, plus a margin (a few late poses cost a little more round trip for every
// pose; fewer poses go unanswered).
#pragma once
#include <atomic>
#include <cstdint>

namespace isotouch::servo {

/// When a link's next input is due [ns, steady clock] and the input's period [ns];
/// due_ns < 0: unknown (fewer than two inputs, or the stream has paused). late_ns: how late
/// behind its predicted time an arrival runs [ns], the 99.5th percentile of the last 256.
struct InputPhase {
  std::int64_t due_ns = -1;
  std::int64_t period_ns = 0;
  std::int64_t late_ns = 0;
};

/// The input's period and phase from its arrival times. arrived(): one thread at a time
/// (the caller's lock); phase(): any thread, lock-free (the two fields may be one arrival
/// apart, which moves the servo by at most a step it takes anyway).
static_assert(std::atomic<std::int64_t>::is_always_lock_free, "the servo reads the phase lock-free");

class ArrivalClock {
 public:
  void arrived(std::int64_t t_ns);
  InputPhase phase() const {
    // Acquire: what the arriving thread stored before the arrival (the pose) is visible.
    return {due_.load(std::memory_order_acquire), period_.load(std::memory_order_relaxed),
            late_.load(std::memory_order_relaxed)};
  }

  static constexpr int kLateWindow = 256;       // arrivals in the lateness percentile
  static constexpr std::int64_t kLateBinNs = 5000;  // its histogram's bin [ns]
  static constexpr int kLateBins = 400;         // 0-2 ms; later arrivals count in the last bin

 private:
  void note_lateness(std::int64_t late_ns);
  void forget_lateness();  // a new stream or rate: the old one's lateness is not this one's
  std::int16_t late_ring_[kLateWindow] = {};  // the window's bins, oldest overwritten first
  std::int32_t late_hist_[kLateBins] = {};    // how many of the window fall in each bin
  int late_count_ = 0, late_next_ = 0;

  std::int64_t last_ns_ = -1;    // the previous arrival
  std::int64_t period_ns_ = 0;   // the smoothed interval; 0: none yet
  std::int64_t anchor_ns_ = -1;  // the smoothed arrival phase (an arrival's time less its jitter)
  int outliers_ = 0;             // intervals in a row far from the period: the rate changed
  int intervals_ = 0;            // intervals in the period's mean, at most 16
  std::atomic<std::int64_t> due_{-1}, period_{0}, late_{0};
};

/// `next_ns` (the servo's next deadline at period `period_ns`) moved by at most period / 16
/// towards the nearest deadline that falls a lead after an arrival of `in`: `lead_ns`, or
/// in.late_ns + kLateMarginNs (at most 3/4 of the period) where that is more; unchanged when
/// `in` is unknown, paused for more than 4 of its periods, or its period is not within 0.5 %
/// of a whole number of servo periods.
inline constexpr std::int64_t kLateMarginNs = 25000;
std::int64_t follow_input_phase(std::int64_t next_ns, std::int64_t period_ns, InputPhase in, std::int64_t lead_ns);

/// A tick placed after an input that has not arrived: until when it waits for it [ns], or -1
/// (no wait). The lead covers all but the latest 0.5 % of arrivals; one later than the tick
/// would wait a whole period and be overtaken by the next (never answered), so the tick
/// waits for it instead, at most until `deadline_ns` + half a servo period (the next tick's
/// time stays where it was). Only where the input is due and followed (its period a whole
/// number of servo periods, as follow_input_phase requires) and due at most a servo period
/// before `t_ns`: an input due longer ago has paused, and none is waited for.
std::int64_t input_wait_until(std::int64_t t_ns, std::int64_t deadline_ns, std::int64_t period_ns, InputPhase in);

}  // namespace isotouch::servo
