#include "isotouch/servo/input_phase.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace isotouch::servo {

void ArrivalClock::arrived(std::int64_t t_ns) {
  const std::int64_t d = last_ns_ >= 0 ? t_ns - last_ns_ : 0;
  last_ns_ = t_ns;
  if (d <= 0) return;
  if (period_ns_ == 0 || outliers_ >= 8) {  // the first interval, or a new rate: start over
    period_ns_ = d;
    anchor_ns_ = t_ns;
    outliers_ = 0;
    intervals_ = 1;
    forget_lateness();
  } else if (2 * d < period_ns_ || 2 * d > 3 * period_ns_) {
    // An arrival over half a period late (but under a whole one: longer is a pause, which
    // no lead covers) is lateness the lead must cover, though it is no period.
    if (d < 2 * period_ns_ && 2 * d > 3 * period_ns_) note_lateness(t_ns - (anchor_ns_ + period_ns_));
    ++outliers_;  // a burst or a gap: neither the period nor the phase
    anchor_ns_ = t_ns;
    due_.store(-1, std::memory_order_release);
    return;
  } else {
    outliers_ = 0;
    intervals_ = std::min(intervals_ + 1, 16);  // the mean of the first 16, then a running one
    // Once learned (16 intervals), one interval moves the period by at most 1/64 / 16 of it
    // (0.1 %): an arrival a third of a period late moved it 2 %, past whole_periods' 0.5 %,
    // so the next tick neither followed nor waited, and a second late pose in a row was
    // overtaken. A new rate comes as intervals far from the period (the outliers above).
    const std::int64_t step = intervals_ < 16 ? d - period_ns_ : std::clamp(d - period_ns_, -period_ns_ / 64, period_ns_ / 64);
    period_ns_ += step / intervals_;
    // The phase: predicted one period on, pulled 1/8 of the way to the arrival; jitter that
    // only ever delays an arrival leaves the anchor near the early ones.
    const std::int64_t predicted = anchor_ns_ + period_ns_;
    const std::int64_t r = t_ns - predicted;
    note_lateness(r);
    anchor_ns_ = predicted + (r < 0 ? r / 2 : r / 8);
  }
  period_.store(period_ns_, std::memory_order_relaxed);
  due_.store(anchor_ns_ + period_ns_, std::memory_order_release);
}

void ArrivalClock::forget_lateness() {
  std::fill(std::begin(late_hist_), std::end(late_hist_), 0);
  late_count_ = late_next_ = 0;
  late_.store(0, std::memory_order_relaxed);
}

void ArrivalClock::note_lateness(std::int64_t late_ns) {
  const auto bin = std::int16_t(std::clamp<std::int64_t>(late_ns / kLateBinNs, 0, kLateBins - 1));
  if (late_count_ == kLateWindow) --late_hist_[late_ring_[late_next_]];
  else ++late_count_;
  late_ring_[late_next_] = bin;
  ++late_hist_[bin];
  late_next_ = (late_next_ + 1) % kLateWindow;
  // The 99.5th percentile: the bin below which all but 0.5 % of the window fall (its top).
  const int beyond = late_count_ / 200;
  int above = 0, b = kLateBins - 1;
  for (; b > 0; --b) {
    if (above + late_hist_[b] > beyond) break;
    above += late_hist_[b];
  }
  late_.store(late_count_ >= 16 ? (b + 1) * kLateBinNs : 0, std::memory_order_relaxed);
}

namespace {
// The input's period is a whole number of servo periods (within 0.5 %): ticks can follow it.
bool whole_periods(InputPhase in, std::int64_t period_ns) {
  if (in.due_ns < 0 || in.period_ns <= 0 || period_ns <= 0) return false;
  const double ratio = double(in.period_ns) / double(period_ns);
  const double whole = std::round(ratio);
  return whole >= 1 && std::abs(ratio - whole) <= 0.005 * whole;
}
}  // namespace

std::int64_t follow_input_phase(std::int64_t next_ns, std::int64_t period_ns, InputPhase in, std::int64_t lead_ns) {
  if (!whole_periods(in, period_ns)) return next_ns;
  if (next_ns - in.due_ns > 4 * in.period_ns) return next_ns;  // the input paused
  const std::int64_t lead = std::max(lead_ns, std::min(in.late_ns + kLateMarginNs, 3 * period_ns / 4));
  // How far the next deadline lies after the wanted one, in (-period/2, period/2].
  std::int64_t e = (next_ns - (in.due_ns + lead)) % period_ns;
  if (e < 0) e += period_ns;
  if (e > period_ns / 2) e -= period_ns;
  return next_ns - std::clamp(e, -period_ns / 16, period_ns / 16);
}

std::int64_t input_wait_until(std::int64_t t_ns, std::int64_t deadline_ns, std::int64_t period_ns, InputPhase in) {
  if (!whole_periods(in, period_ns)) return -1;
  if (in.due_ns > t_ns || t_ns - in.due_ns > period_ns) return -1;  // arrived (due moved on), or paused
  const std::int64_t until = deadline_ns + period_ns / 2;
  return until > t_ns ? until : -1;
}

}  // namespace isotouch::servo
