#include "servo_thread.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <cerrno>
#include <algorithm>
#include <cstring>

namespace isotouch::servo {
namespace {
inline std::int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);  // vDSO: no syscall
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}
}  // namespace

ServoThread::ServoThread(TripleBuffer<SampleField>& samples, HriRenderer& renderer,
                         HapticDeviceIO& device, ServoThreadConfig config)
    : samples_(samples), renderer_(renderer), device_(device), cfg_(std::move(config)) {
  period_err_.reserve(cfg_.record_ticks);
}

ServoThread::~ServoThread() { stop(); }

std::string ServoThread::start() {
  stop_.store(false);
  period_err_.clear();
  thread_ = std::thread([this] { loop(); });
  std::string note;
  if (cfg_.sched_fifo) {
    sched_param sp{};
    sp.sched_priority = cfg_.fifo_priority;
    const int rc = pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &sp);
    if (rc != 0)
      note += "SCHED_FIFO priority " + std::to_string(cfg_.fifo_priority) + " not permitted (" +
              std::strerror(rc) + "; needs CAP_SYS_NICE or an rtprio limit): running with the default scheduler. ";
  }
  if (cfg_.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cfg_.cpu, &set);
    const int rc = pthread_setaffinity_np(thread_.native_handle(), sizeof(set), &set);
    if (rc != 0) note += "pinning to CPU " + std::to_string(cfg_.cpu) + " failed (" + std::strerror(rc) + "). ";
  }
  return note;
}

void ServoThread::stop() {
  stop_.store(true, std::memory_order_relaxed);
  if (thread_.joinable()) thread_.join();
}

void ServoThread::loop() {
  if (cfg_.on_thread_start) cfg_.on_thread_start();
  const std::int64_t period = std::int64_t(1e9 / cfg_.rate_hz + 0.5);
  // Spin at most 30 % of a period: a thread that never sleeps is throttled under
  // SCHED_FIFO (sched_rt_runtime_us) and starves the engine thread on small machines.
  const std::int64_t spin = std::min(std::int64_t(cfg_.spin_us * 1e3), std::int64_t(0.3 * double(period)));
  std::int64_t next = now_ns();
  std::int64_t prev_start = -1;
  std::uint64_t last_version = 0;
  while (!stop_.load(std::memory_order_relaxed)) {
    next += period;
    // Wait: sleep to just before the deadline, then spin (outside the tick).
    std::int64_t t = now_ns();
    if (next - spin > t) {
      const std::int64_t wake = next - spin;
      timespec ts{time_t(wake / 1000000000LL), long(wake % 1000000000LL)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
    }
    while ((t = now_ns()) < next) cpu_relax();
    if (t - next >= period) {  // started a whole period late: missed; re-anchor
      missed_.fetch_add((t - next) / period, std::memory_order_relaxed);
      next = t;
    }
    if (prev_start >= 0 && period_err_.size() < period_err_.capacity())
      period_err_.push_back((t - prev_start) - period);  // capacity reserved: no allocation
    prev_start = t;

    // ---- the tick: no allocation, no lock, no syscall ----
    const SampleField* field = samples_.acquire();
    if (!field) {
      device_.write_force_n({});
      empty_.fetch_add(1, std::memory_order_relaxed);
    } else {
      if (field->version != last_version) {
        last_version = field->version;
        snapshot_changes_.fetch_add(1, std::memory_order_relaxed);
      }
      const Vec3 x = device_.read_position_m();
      const HriTick out = renderer_.tick(*field, cfg_.world_T_device.to_world(x));
      device_.write_force_n(out.force_n);
      if (out.fault) faults_.fetch_add(1, std::memory_order_relaxed);
    }
    ticks_.fetch_add(1, std::memory_order_relaxed);
  }
  device_.write_force_n({});  // leave the device with no force
}

}  // namespace isotouch::servo
