#include "isotouch/servo/servo_thread.h"

#include <pthread.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/exit_zero.h"

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

/// Touch kBytes of this thread's stack below the caller's frame so the loop never takes a
/// page fault growing it (with memory locked, the pages stay).
__attribute__((noinline)) void prefault_stack() {
  volatile unsigned char buf[kServoStackBytes];
  for (std::size_t i = 0; i < sizeof(buf); i += 4096) buf[i] = 0;
  buf[sizeof(buf) - 1] = 0;
}

/// The status the servo acts on at tick start `t`: the device's own; stale when an
/// asynchronous report is older than `stale_ns`; fault with `refused` set when an ok
/// report's position is non-finite or outside the device's workspace box.
DeviceStatus judge(const DeviceReading& d, std::int64_t t, std::int64_t stale_ns, const DeviceCaps& caps,
                   bool& refused) {
  refused = false;
  if (d.status != DeviceStatus::kOk) return d.status;
  if (d.received_ns != 0 && t - d.received_ns > stale_ns) return DeviceStatus::kStale;
  if (!caps.contains(d.position_m)) {
    refused = true;
    return DeviceStatus::kFault;
  }
  return DeviceStatus::kOk;
}

// A device with its own writer takes the force off after this many periods without a write.
constexpr double kStallPeriods = 2.5;
// Handoff::state: where the servo thread is, and whether stop() gave up on it.
constexpr int kOutside = 0, kInRenderer = 1, kAbandoned = 2;
// The live passivity stage's own |F| clip [N]: far above any device's peak.
constexpr double kPassivityClipN = 1e9;


}  // namespace

ServoThread::ServoThread(TripleBuffer<SampleField>& samples, Renderer& renderer,
                         HapticDeviceIO& device, ServoThreadConfig config)
    : samples_(samples), renderer_(renderer), device_(device), cfg_(std::move(config)) {
  // The period is 1e9 / rate_hz ns: a rate of 0, below 0 or not a number has none, and
  // above 1 MHz it is under a microsecond.
  if (!(cfg_.rate_hz > 0) || !std::isfinite(cfg_.rate_hz) || cfg_.rate_hz > 1e6)
    throw std::invalid_argument("servo thread: rate_hz must be in (0, 1e6] Hz, got " + std::to_string(cfg_.rate_hz));
  period_err_.reserve(cfg_.record_ticks);
}

ServoThread::~ServoThread() { stop(); }

std::string ServoThread::start() {
  stop();
  if (abandoned_)
    throw std::logic_error("servo thread: start() after stop() abandoned a thread stuck in the renderer");
  stop_.store(false);
  ready_.store(false);
  period_err_.clear();
  caps_ = device_.caps();
  if (caps_.output_rate_hz > 0 && cfg_.rate_hz > caps_.output_rate_hz * 1.001)
    throw std::invalid_argument("servo thread: servo rate " + std::to_string(cfg_.rate_hz) + " Hz is above " +
                                caps_.name + "'s own output loop (" + std::to_string(caps_.output_rate_hz) +
                                " Hz): its ticks between two of the device's would be lost; run the servo at " +
                                "or below the device's rate");
  ForceLimits limits = force_limits(caps_, cfg_.force_limit_n, cfg_.max_force_rate_n_per_s);
  limits.rate_dt_cap_s = 1.0 / cfg_.rate_hz;  // a late tick changes the force no more than an on-time one
  gate_ = ForceGate(limits);
  const double alpha_max = cfg_.passivity_alpha_max_n_s_per_m > 0 ? cfg_.passivity_alpha_max_n_s_per_m
                           : std::isfinite(caps_.max_damping_n_s_per_m) ? caps_.max_damping_n_s_per_m
                                                                        : kDefaultPassivityAlphaS * cfg_.rate_hz;
  // Its own clip out of the way: the gate clamps (and counts it), and the observer books
  // what the gate let through.
  passivity_.start(cfg_.passivity_control, alpha_max, kPassivityClipN, 1.0 / cfg_.rate_hz);
  device_stalls_ = device_.enable_force(true, kStallPeriods / cfg_.rate_hz);
  seen_stalls_ = device_stalls_ ? device_stalls_->load(std::memory_order_acquire) : 0;
  handoff_ = std::make_shared<Handoff>();
  thread_ = std::thread([this, h = handoff_] {
    ensure_signal_stack();  // a stack overflow in the renderer still sends the links' zeros
    loop(*h);
    h->done.store(true, std::memory_order_release);
  });
  ready_.wait(false, std::memory_order_acquire);  // the real-time setup is done
  return setup_note_;
}

std::string ServoThread::stop() {
  stop_.store(true, std::memory_order_relaxed);
  std::string error;
  if (thread_.joinable()) {
    // Abandoned only while inside the renderer: anywhere else the loop ends on its own.
    int in = kInRenderer;
    if (!wait_done(*handoff_) && handoff_->state.compare_exchange_strong(in, kAbandoned, std::memory_order_acq_rel)) {
      thread_.detach();
      abandoned_ = true;
      error = "servo thread: the renderer has not returned for " + std::to_string(cfg_.stop_timeout_s) +
              " s: force turned off, the thread abandoned";
    } else {
      thread_.join();
    }
    device_.enable_force(false, 0);
  }
  unlock_servo_memory();
  return error;
}

bool ServoThread::wait_done(const Handoff& h) const {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::duration<double>(cfg_.stop_timeout_s);
  while (!h.done.load(std::memory_order_acquire)) {
    if (std::chrono::steady_clock::now() >= give_up) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

std::string ServoThread::setup_realtime() {
  std::string note;
  got_lock_ = !locked_.empty();
  // Sleep wake-ups exactly on time (the default slack of a normal thread is 50 us).
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  // Automatic pinning only with SCHED_FIFO (make_thread_realtime).
  const RealtimeSetup rt =
      make_thread_realtime("servo thread", cfg_.sched_fifo, cfg_.fifo_priority, cfg_.pin_cpu, cfg_.cpu);
  got_fifo_ = rt.fifo;
  pinned_cpu_ = rt.cpu;
  note += rt.note;
  // Prefault what the loop touches: its stack and the record buffer (written once, so the
  // pages exist and, locked, stay). The field is written by the engine before it is
  // published, so its pages already exist.
  prefault_stack();
  period_err_.assign(period_err_.capacity(), 0);
  period_err_.clear();  // keeps the capacity and the touched pages
  if (cfg_.lock_memory && locked_.empty()) note += lock_servo_memory();
  return note;
}

namespace {
/// [data, data + bytes) widened to whole pages.
MemoryRange whole_pages(const void* data, std::size_t bytes) {
  const auto page = std::uintptr_t(sysconf(_SC_PAGESIZE));
  const auto lo = std::uintptr_t(data) & ~(page - 1);
  const auto hi = (std::uintptr_t(data) + bytes + page - 1) & ~(page - 1);
  return {reinterpret_cast<const void*>(lo), hi - lo};
}

/// The calling thread's stack from `bytes` below the caller's frame to its top (the frames
/// above the loop's). Empty if the stack cannot be found.
__attribute__((noinline)) MemoryRange own_stack(std::size_t bytes) {
  pthread_attr_t attr;
  if (pthread_getattr_np(pthread_self(), &attr) != 0) return {};
  void* base = nullptr;
  std::size_t size = 0;
  const int rc = pthread_attr_getstack(&attr, &base, &size);
  pthread_attr_destroy(&attr);
  if (rc != 0) return {};
  const auto lo = std::uintptr_t(base), top = lo + size;
  const auto here = std::uintptr_t(__builtin_frame_address(0));
  const std::uintptr_t from = here - lo > bytes ? here - bytes : lo;
  return {reinterpret_cast<const void*>(from), top - from};
}
}  // namespace

// What each tick touches, and nothing else of the process: mlockall would lock every load,
// undo step and heap for the whole session (MADV_DONTNEED then fails: freed memory stays).
// Snapshots are not locked: they are replaced at the edit rate and share bricks between
// versions, and mlock is not counted, so unlocking an old one could unlock a page the new
// one still uses; the engine writes each just before publishing it (resident when read).
std::string ServoThread::lock_servo_memory() {
  std::vector<MemoryRange> want = {own_stack(kServoStackBytes + 16 * 1024),
                                   {period_err_.data(), period_err_.capacity() * sizeof(std::int64_t)},
                                   {this, sizeof(*this)}};
  want.insert(want.end(), cfg_.lock_ranges.begin(), cfg_.lock_ranges.end());
  locked_bytes_ = 0;
  for (const MemoryRange& r : want) {
    if (r.data == nullptr || r.bytes == 0) continue;
    const MemoryRange p = whole_pages(r.data, r.bytes);
    if (mlock(p.data, p.bytes) != 0) {
      const std::string e = std::strerror(errno);
      unlock_servo_memory();
      locked_bytes_ = 0;
      return "servo thread: mlock of " + std::to_string(p.bytes / 1024) + " KiB refused (" + e +
             "; needs root, CAP_IPC_LOCK or a memlock limit): memory not locked.\n";
    }
    locked_.push_back(p);
    locked_bytes_ += p.bytes;
  }
  got_lock_ = !locked_.empty();
  return "";
}

void ServoThread::unlock_servo_memory() {
  for (const MemoryRange& r : locked_) munlock(r.data, r.bytes);  // (a stack since unmapped: ENOMEM, nothing to do)
  locked_.clear();
}

std::int64_t ServoThread::wait_for_input(std::int64_t t, std::int64_t next, std::int64_t period) {
  const InputPhase in = device_.input_phase();
  const std::int64_t until = input_wait_until(t, next, period, in);
  if (until < 0) return t;
  // Slept in short slices, not spun: the thread that receives the pose may be queued on this
  // CPU behind a real-time servo that never sleeps (a 2-CPU machine), and a spin would hold
  // off the very arrival it waits for.
  constexpr std::int64_t kSliceNs = 20'000;
  while (t < until && device_.input_phase().due_ns == in.due_ns) {
    const timespec ts{0, long(std::min(kSliceNs, until - t))};
    nanosleep(&ts, nullptr);
    t = now_ns();
  }
  input_waits_.fetch_add(1, std::memory_order_relaxed);
  if (t >= until) input_wait_timeouts_.fetch_add(1, std::memory_order_relaxed);  // the pose did not come
  return t;
}

void ServoThread::loop(Handoff& h) {
  setup_note_ = setup_realtime();
  ready_.store(true, std::memory_order_release);
  ready_.notify_all();
  if (cfg_.on_thread_start) cfg_.on_thread_start();

  const std::int64_t period = std::int64_t(1e9 / cfg_.rate_hz + 0.5);
  const std::int64_t spin = std::min(std::int64_t(cfg_.spin_us * 1e3),
                                     std::int64_t(std::clamp(cfg_.max_spin_fraction, 0.0, 1.0) * double(period)));
  std::int64_t next = now_ns();
  std::int64_t prev_start = -1;
  Vec3 last_hip;  // the last tick's HIP, world [m], buttons and status: the stop's held tick records them
  std::uint32_t last_buttons = 0;
  DeviceStatus last_status = DeviceStatus::kOk;
  std::int64_t last_render = -1;  // start of the renderer's last tick; -1: none since a reset
  std::uint64_t last_version = 0;
  bool was_paused = false;
  std::int64_t gate_prev = -1;  // the gate's last step or zero; -1: none yet
  const std::int64_t stale_ns =
      cfg_.stale_timeout_s > 0   ? std::int64_t(cfg_.stale_timeout_s * 1e9)
      : caps_.stale_timeout_s > 0 ? std::int64_t(caps_.stale_timeout_s * 1e9)
                                  : 2 * period;
  const double ramp_ns = std::max(cfg_.ramp_in_s, 0.0) * 1e9;
  std::int64_t ramp_start = -1;  // tick start of the ramp in progress; -1: (re)start it
  std::int64_t not_ok_since = -1;  // start of the current run of not-ok ticks; -1: none
  const auto restart_ns = std::int64_t(std::max(cfg_.stale_restart_s, 0.0) * 1e9);
  std::uint32_t connection = 0;
  bool first = true;
  const auto input_lead = std::int64_t(std::clamp(std::isfinite(cfg_.input_lead_us) ? cfg_.input_lead_us : 100.0, 0.0, 1e6) * 1e3);
  while (!stop_.load(std::memory_order_relaxed)) {
    next += period;
    if (cfg_.follow_input_phase) next = follow_input_phase(next, period, device_.input_phase(), input_lead);
    // Wait: sleep to just before the deadline, then spin (outside the tick).
    std::int64_t t = now_ns();
    if (next - spin > t) {
      const std::int64_t wake = next - spin;
      timespec ts{time_t(wake / 1000000000LL), long(wake % 1000000000LL)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
    }
    while ((t = now_ns()) < next) cpu_relax();
    if (cfg_.follow_input_phase) t = wait_for_input(t, next, period);
    if (t - next >= period) {  // started a whole period late: missed; re-anchor
      missed_.fetch_add((t - next) / period, std::memory_order_relaxed);
      next = t;
    }
    // The measured period: 0 on the first tick. The renderer is given the time since it last
    // ran (a stale blip that kept its state is in its velocity's time step), 0 after a reset
    // (the nominal period).
    const double period_s = prev_start >= 0 ? double(t - prev_start) * 1e-9 : 0.0;
    const double dt_s = last_render >= 0 ? double(t - last_render) * 1e-9 : 0.0;
    if (prev_start >= 0 && period_err_.size() < period_err_.capacity())
      period_err_.push_back((t - prev_start) - period);  // capacity reserved: no allocation
    prev_start = t;

    // ---- the tick: no allocation, no lock, no syscall ----
    const SampleField* field = samples_.acquire();
    const bool paused = paused_.load(std::memory_order_relaxed);
    // Since the gate's last tick; the first tick is given the nominal period.
    const double gate_dt = gate_prev >= 0 ? double(t - gate_prev) * 1e-9 : 1.0 / cfg_.rate_hz;
    gate_prev = t;
    if (!field) {
      device_.write_force_n({});
      gate_.zero(gate_dt);
      passivity_.sent({});
      empty_.fetch_add(1, std::memory_order_relaxed);
    } else {
      if (field->version != last_version) {
        last_version = field->version;
        snapshot_changes_.fetch_add(1, std::memory_order_relaxed);
      }
      TickRecord rec;
      rec.k = ticks_.load(std::memory_order_relaxed);
      rec.t_ns = t;
      rec.dt_s = dt_s;
      rec.period_s = period_s;
      rec.version = field->version;
      const DeviceReading d = device_.read();
      if (first || d.connection != connection) ramp_start = -1;  // enabled, or reconnected
      if (!first && d.connection != connection) passivity_.restart();  // a new device: no old books
      // The device's force is off (its watchdog tripped): ramp in from 0 when it is back on.
      if ((d.force_off || d.watchdog_tripped) && ramp_start >= 0) ramp_start = t;
      first = false;
      connection = d.connection;
      rec.buttons = d.buttons;
      rec.hip_m = cfg_.world_T_device.to_world(d.position_m);
      last_hip = rec.hip_m;
      last_buttons = d.buttons;
      rec.report_ns = d.received_ns;
      rec.paused = paused;
      bool refused = false;
      rec.device_status = judge(d, t, stale_ns, caps_, refused);
      last_status = rec.device_status;
      status_.store(std::uint8_t(rec.device_status), std::memory_order_relaxed);
      if (rec.device_status != DeviceStatus::kOk) {
        device_.write_force_n({});  // within this tick
        gate_.zero(gate_dt);
        // A stale report is a real, old position: its motion is booked. Any other bad reading
        // is not (a lost or faulty device's position): the motion over it books no work.
        if (rec.device_status == DeviceStatus::kStale) passivity_.skip(t, d.device_time_us, d.position_m);
        passivity_.sent({});
        count_not_ok(rec.device_status, refused);
        if (not_ok_since < 0) not_ok_since = t;
        // A blip of stale ticks keeps the contact state and the force level; anything
        // longer, or a device that was lost or faulty, starts over with a ramp.
        if (rec.device_status != DeviceStatus::kStale || t - not_ok_since > restart_ns) {
          ramp_start = -1;
          was_paused = true;  // the renderer is reset before the next good tick
          last_render = -1;
        }
      } else if (paused) {
        device_.write_force_n({});
        gate_.zero(gate_dt);
        passivity_.skip(t, d.device_time_us, d.position_m);
        passivity_.sent({});
        was_paused = true;
        last_render = -1;
        ramp_start = -1;  // resumed: ramp in again
      } else {
        if (was_paused) {
          renderer_.reset();
          rec.reset = true;
        }
        was_paused = false;
        not_ok_since = -1;
        if (ramp_start < 0) {
          ramp_start = t;
          ramps_.fetch_add(1, std::memory_order_relaxed);
        }
        // Everything the call needs is read before the handoff: stop() may abandon the thread
        // and this object may be gone while the renderer runs.
        Renderer& renderer = renderer_;
        h.state.store(kInRenderer, std::memory_order_release);
        rec.out = renderer.tick(*field, rec.hip_m, dt_s);
        if (int in = kInRenderer; !h.state.compare_exchange_strong(in, kOutside, std::memory_order_acq_rel))
          return;  // abandoned by stop(): touch nothing (this object may be gone)
        last_render = t;
        // The device took the force off (the servo did not write for 2.5 periods: a late
        // tick, a slow renderer): ramp in from 0 again, this tick's force being zero.
        const std::uint64_t stalls = device_stalls_ ? device_stalls_->load(std::memory_order_acquire) : 0;
        if (stalls != seen_stalls_) {
          late_.fetch_add(1, std::memory_order_relaxed);
          ramp_start = -1;  // the next tick starts the ramp
        }
        seen_stalls_ = stalls;
        double ramp = ramp_ns > 0 ? std::min(1.0, double(t - ramp_start) / ramp_ns) : 1.0;
        std::uint8_t gated = 0;
        // An exact zero, the gate rising from it afterwards: the device took the force off (a
        // stall: the ramp restarts next tick), the ramp starts on this tick (enable, a
        // reconnection, the device's force off or its watchdog), or the renderer reports a
        // fault (its force is not to be ramped down, it is to stop).
        if (ramp_start < 0 || ramp == 0 || rec.out.fault) {
          rec.force_sent_n = {};
          gate_.zero(gate_dt);
          passivity_.skip(t, d.device_time_us, d.position_m);  // the held force's work is booked
        } else {
          // The passivity stage before the gate: the gate's limits hold whatever it adds.
          const Vec3 damped = passivity_.step(t, d.device_time_us, d.position_m, rec.out.force_n * ramp);
          rec.force_sent_n = gate_.step(damped, gate_dt, gated);
          rec.passivity_clock_s = passivity_.last_clock_s();
        }
        passivity_.sent(rec.force_sent_n);  // the observer books what was written
        if (gated & kGatePeak) clamped_.fetch_add(1, std::memory_order_relaxed);
        if (gated & kGateRate) rate_limited_.fetch_add(1, std::memory_order_relaxed);
        if (gated & kGateContinuous) continuous_limited_.fetch_add(1, std::memory_order_relaxed);
        device_.answer(d.sequence);
        device_.write_force_n(rec.force_sent_n);
        if (rec.out.fault) faults_.fetch_add(1, std::memory_order_relaxed);
      }
      if (cfg_.observer) cfg_.observer->on_tick(rec);
    }
    ticks_.fetch_add(1, std::memory_order_relaxed);
  }
  // Record the zero left on the device as the last tick (held: the renderer not ticked; the
  // HIP of the tick before), so a recording ends with what the device was left with.
  const std::int64_t t_stop = now_ns();
  device_.write_force_n({});  // leave the device with no force
  if (const SampleField* field = samples_.acquire(); field && cfg_.observer && prev_start >= 0) {
    TickRecord rec;
    rec.k = ticks_.load(std::memory_order_relaxed);
    rec.t_ns = t_stop;
    rec.period_s = 0;  // not a scheduled period: no period error, no renderer step
    rec.version = field->version;
    rec.hip_m = last_hip;
    rec.buttons = last_buttons;  // a button held at the stop is not a release
    rec.device_status = last_status;
    rec.paused = true;
    cfg_.observer->on_tick(rec);
    ticks_.fetch_add(1, std::memory_order_relaxed);
  }
  device_.enable_force(false, 0);  // at once: the writes end here, which is no stall
}

void ServoThread::count_not_ok(DeviceStatus s, bool refused) {
  if (refused) refused_.fetch_add(1, std::memory_order_relaxed);
  else if (s == DeviceStatus::kStale) stale_.fetch_add(1, std::memory_order_relaxed);
  else if (s == DeviceStatus::kDisconnected) disconnected_.fetch_add(1, std::memory_order_relaxed);
  else if (s == DeviceStatus::kUncalibrated) uncalibrated_.fetch_add(1, std::memory_order_relaxed);
  else dev_fault_.fetch_add(1, std::memory_order_relaxed);
}

DeviceCounters ServoThread::device_counters() const {
  DeviceCounters c;
  c.stale = stale_.load(std::memory_order_relaxed);
  c.disconnected = disconnected_.load(std::memory_order_relaxed);
  c.fault = dev_fault_.load(std::memory_order_relaxed);
  c.uncalibrated = uncalibrated_.load(std::memory_order_relaxed);
  c.refused = refused_.load(std::memory_order_relaxed);
  c.ramps = ramps_.load(std::memory_order_relaxed);
  c.clamped = clamped_.load(std::memory_order_relaxed);
  c.rate_limited = rate_limited_.load(std::memory_order_relaxed);
  c.continuous_limited = continuous_limited_.load(std::memory_order_relaxed);
  c.late_restarts = late_.load(std::memory_order_relaxed);
  return c;
}

}  // namespace isotouch::servo
