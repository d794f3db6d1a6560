#include "isotouch/servo/stall_rule.h"

#include <algorithm>
#include <cmath>

namespace isotouch::servo {

void StallRule::write(const Vec3& force_n, std::uint64_t answers, std::int64_t now_ns) {
  const bool ok = std::isfinite(force_n.x) && std::isfinite(force_n.y) && std::isfinite(force_n.z);
  Vec3 f = ok ? force_n : Vec3{};
  const std::uint64_t stalls = stalls_.load(std::memory_order_acquire);
  if (stalls != stalls_seen_) f = Vec3{};  // the first write after a stall: no jump back
  stalls_seen_ = stalls;
  cell_.store(Output{f, answers, ++writes_, stalls, now_ns});
}

const std::atomic<std::uint64_t>* StallRule::enable(bool on, double stall_s, double default_s, std::int64_t now_ns,
                                                    double look_period_s) {
  if (!(stall_s > 0) || !std::isfinite(stall_s)) stall_s = default_s;
  const double p = std::isfinite(look_period_s) && look_period_s > 0 ? look_period_s : 0.0;
  // The first look after last write + stall time comes at most one period later.
  stall_ns_.store(std::llround(std::max(stall_s - p / 2, p) * 1e9), std::memory_order_relaxed);
  enabled_ns_.store(now_ns, std::memory_order_relaxed);
  enabled_.store(on, std::memory_order_release);
  return &stalls_;
}

void StallRule::restart(std::int64_t now_ns) {
  seen_count_ = cell_.load().count;
  seen_at_ = last_at_ = now_ns;
  was_on_ = false;
}

StallLook StallRule::look(std::int64_t now_ns) {
  StallLook l;
  const Output o = cell_.load();
  l.fresh = o.count != seen_count_;
  if (l.fresh) {
    l.new_writes = o.count - seen_count_;
    seen_count_ = o.count, seen_at_ = now_ns;
    last_at_ = o.written_ns != 0 ? std::min(o.written_ns, now_ns) : now_ns;
  }
  bool on = enabled_.load(std::memory_order_acquire) && last_at_ >= enabled_ns_.load(std::memory_order_relaxed);
  const bool stalled = now_ns - last_at_ > stall_ns_.load(std::memory_order_relaxed);
  if (on && was_on_ && stalled) {
    stalls_.fetch_add(1, std::memory_order_release);
    l.stalled_now = true;
  }
  if (o.stalls != stalls_.load(std::memory_order_relaxed)) on = false;
  was_on_ = on;
  l.on = on;
  l.force_n = on ? o.force_n : Vec3{};
  l.answers = o.answers;
  l.last_write_ns = last_at_;
  return l;
}

}  // namespace isotouch::servo
