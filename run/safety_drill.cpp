#include "isotouch/run/safety_drill.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <memory>
#include <ostream>
#include <thread>
#include <vector>

#include "isotouch/servo/force_gate.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/triple_buffer.h"

namespace isotouch::run {
namespace {
using core::Vec3;

/// Zero for `step_at` ticks (the ramp-in is over by then), then `f` up the device's z (a step
/// demand); one tick (after `stall_after` ticks) takes `stall_ms`.
class DrillPush final : public servo::Renderer {
 public:
  DrillPush(double f, long step_at, long stall_after, int stall_ms)
      : f_(f), step_at_(step_at), stall_after_(stall_after), stall_ms_(stall_ms) {}
  const char* name() const override { return "safety drill"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView&, const Vec3&, double) override {
    if (++ticks_ == stall_after_) std::this_thread::sleep_for(std::chrono::milliseconds(stall_ms_));
    servo::HriTick t;
    if (ticks_ > step_at_) t.force_n = {0, 0, f_};
    return t;
  }

 private:
  double f_;
  long step_at_, stall_after_;
  int stall_ms_;
  long ticks_ = 0;
};

/// Every tick's start and the force sent (preallocated).
struct DrillLog final : servo::TickObserver {
  explicit DrillLog(std::size_t capacity) : t_ns(capacity), f(capacity) {}
  void on_tick(const servo::TickRecord& r) noexcept override {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i >= t_ns.size()) return;
    t_ns[i] = r.t_ns, f[i] = r.force_sent_n.z;
    n.store(i + 1, std::memory_order_release);
  }
  std::vector<std::int64_t> t_ns;
  std::vector<double> f;
  std::atomic<std::size_t> n{0};
};

const char* verdict(bool ok) { return ok ? "held" : "NOT held"; }

/// The first of the log's first `n` ticks that came more than 0.8 x `stall_ms` after the one
/// before it (the renderer's stall), or n.
std::size_t stall_end(const DrillLog& log, std::size_t n, int stall_ms) {
  for (std::size_t i = 1; i < n; ++i)
    if (double(log.t_ns[i] - log.t_ns[i - 1]) * 1e-6 > stall_ms * 0.8) return i;
  return n;
}

/// The first tick at or after `from` (of the first `n`) that sent at least 0.99 x `f`, or n.
std::size_t force_back(const DrillLog& log, std::size_t from, std::size_t n, double f) {
  for (std::size_t i = from; i < n; ++i)
    if (log.f[i] > 0.99 * f) return i;
  return n;
}
}  // namespace

bool run_safety_drill(servo::HapticDeviceIO& device, const SafetyDrillOptions& o, std::ostream& out) {
  const servo::DeviceCaps caps = device.caps();
  const double rate_hz = caps.output_rate_hz > 0 ? std::min(o.rate_hz, caps.output_rate_hz) : o.rate_hz;
  const double f = std::min(o.force_n, caps.max_force_n);
  const auto step_at = long(0.2 * rate_hz);  // past the servo's 50 ms ramp-in
  const auto stall_after = step_at + long(o.push_s * rate_hz);
  servo::TripleBuffer<core::SampleField> none;  // the drill reads no field
  none.publish(std::make_shared<const core::SampleField>());
  DrillPush push(f, step_at, stall_after, o.stall_ms);
  constexpr double kBackWaitS = 3.0;  // the most the drill waits for the force after the stall
  DrillLog log(std::size_t((2 * o.push_s + 1.5 + kBackWaitS) * rate_hz) + 64);
  servo::ServoThreadConfig sc;
  sc.rate_hz = rate_hz;
  sc.force_limit_n = f;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = false;
  sc.observer = &log;
  servo::ServoThread servo(none, push, device, sc);
  const double rate_limit = servo::force_limits(caps, f).rate_n_per_s;
  servo.start();
  std::this_thread::sleep_for(std::chrono::duration<double>(0.2 + 2 * o.push_s + o.stall_ms * 1e-3));
  // The ramp after the stall takes 50 ms, restarted by every tick more than 2 periods late (a
  // loaded machine's, this servo not being real-time): wait for the force to be back, up to
  // kBackWaitS more, rather than judge it at a fixed time.
  for (const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(kBackWaitS);
       std::chrono::steady_clock::now() < until;) {
    const std::size_t k = log.n.load(std::memory_order_acquire);
    if (force_back(log, stall_end(log, k, o.stall_ms), k, f) < k) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  servo.stop();
  const servo::DeviceCounters dc = servo.device_counters();
  const std::size_t n = log.n.load();
  // 1. The step 0 -> f: no tick's change above the rate limit times the ticks' distance.
  bool step_ok = n > std::size_t(step_at) + 2;
  double rise_ms = NAN;
  std::size_t first = n;  // the first tick with force after the step
  for (std::size_t i = 1; i < n; ++i) {
    const double dt = double(log.t_ns[i] - log.t_ns[i - 1]) * 1e-9;
    if (log.f[i] - log.f[i - 1] > rate_limit * dt + 1e-9) step_ok = false;
    if (first == n && log.f[i] > 0) first = i;
    if (first < n && std::isnan(rise_ms) && log.f[i] >= f - 1e-9)
      rise_ms = double(log.t_ns[i] - log.t_ns[first - 1]) * 1e-6;
  }
  // More than one tick to rise: the step was spread (at 1 kHz and 1 N, 2 ms).
  step_ok = step_ok && rise_ms > 1.5e3 / rate_hz;
  out << std::fixed << std::setprecision(1) << "drill    a step 0 -> " << f << " N rose over " << rise_ms
      << " ms (rate limit " << rate_limit << " N/s): " << verdict(step_ok) << "\n";
  // 2. The stall: a device with a thread of its own took the force off and the servo ramped
  // in again: the first tick after the stall sent (close to) nothing.
  const std::size_t after = stall_end(log, n, o.stall_ms);
  const bool own_writer = device.enable_force(false, 0) != nullptr;
  bool stall_ok = after < n;
  if (own_writer) stall_ok = stall_ok && dc.late_restarts >= 1 && log.f[after] < 0.1 * f;
  out << "drill    a " << o.stall_ms << " ms renderer stall: ";
  if (after == n) out << "not seen in the servo's ticks";
  else if (own_writer)
    out << "the device took the force off (" << dc.late_restarts << " stall(s)), the first force after it "
        << std::setprecision(3) << log.f[after] << " N (from the ramp)";
  else out << "this device is written to directly and keeps its last force through a stall (no thread of its own)";
  out << ": " << verdict(stall_ok) << "\n";
  // 3. The ramp after the stall reached the force again.
  const std::size_t back_at = after < n ? force_back(log, after, n, f) : n;
  const bool back = back_at < n;
  out << "drill    the force back to " << std::setprecision(3) << f << " N: ";
  if (back) out << std::setprecision(1) << double(log.t_ns[back_at] - log.t_ns[after]) * 1e-6 << " ms after the stall";
  else out << "not within " << std::setprecision(1) << kBackWaitS << " s of the stall (last " << std::setprecision(3)
           << (n > 0 ? log.f[n - 1] : 0.0) << " N)";
  out << ": " << verdict(back) << "\n";
  return step_ok && stall_ok && back;
}

}  // namespace isotouch::run
