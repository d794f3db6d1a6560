// servo_thread.h - the fixed-rate real-time servo thread.
#pragma once
#include "isotouch/servo/core_names.h"
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/servo/device_io.h"
#include "isotouch/servo/force_gate.h"
#include "isotouch/servo/live_passivity.h"
#include "isotouch/servo/memory_range.h"
#include "isotouch/servo/renderer.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/servo/workspace.h"

namespace isotouch::servo {

/// One servo tick as the servo thread ran it: what the device gave, what the renderer
/// answered, and when. Handed to a TickObserver on the servo thread.
struct TickRecord {
  long k = 0;                 ///< tick index (0 = the first tick)
  std::int64_t t_ns = 0;      ///< the tick's start, CLOCK_MONOTONIC [ns]
  double dt_s = 0;            ///< passed to the renderer: the time since its previous tick [s] (0 on its
                              ///< first tick and after a reset: the nominal period)
  double period_s = 0;        ///< the loop's measured period since its previous tick [s] (0 on the first)
  Vec3 hip_m;                 ///< HIP, world [m] (the device reading mapped)
  std::uint32_t buttons = 0;  ///< the device's buttons (bit i: button i down)
  HriTick out;                ///< the renderer's answer (force, VHIP, plane, contact, fault)
  std::uint64_t version = 0;  ///< SampleField::version of the snapshot the tick read
  bool paused = false;        ///< paused (or the stop's last tick): zero force sent, the renderer not ticked
  /// The renderer was reset before this tick (the first good tick after a pause, a device
  /// outage or a fault): a replay resets it at the same tick.
  bool reset = false;
  /// The device's status as the servo judged it (stale: no report within the timeout;
  /// fault: the device said so or the report was refused). Not ok: zero force was sent and
  /// the renderer was not ticked.
  DeviceStatus device_status = DeviceStatus::kOk;
  Vec3 force_sent_n;          ///< what was written: out.force_n ramped in and clamped [N], device axes
  std::int64_t report_ns = 0; ///< when the host received the report this tick read [ns] (0: synchronous)
  /// The clock the passivity stage (live_passivity.h) stepped on this tick [s] since its
  /// first tick (the device's where it has one); -1: the stage did not step (a held tick).
  double passivity_clock_s = -1;
};

/// Sees every tick on the servo thread, after the force was written. on_tick() runs inside
/// the tick: it must allocate nothing, take no lock and make no syscall (push into
/// preallocated lock-free queues, store atomics).
class TickObserver {
 public:
  virtual ~TickObserver() = default;
  virtual void on_tick(const TickRecord& tick) noexcept = 0;
};

/// The part of the servo thread's stack that is prefaulted and locked before the first
/// tick, below the loop's frame [bytes].
inline constexpr std::size_t kServoStackBytes = 256 * 1024;

struct ServoThreadConfig {
  double rate_hz = 1000;          ///< servo rate, 1 to 10 kHz [Hz]
  /// Ask for SCHED_FIFO at fifo_priority before the first tick (needs root, CAP_SYS_NICE or
  /// an rtprio limit). Refused: the loop runs under the default scheduler and start() says so.
  bool sched_fifo = true;
  int fifo_priority = 80;         ///< SCHED_FIFO priority, 1 to 99
  /// Pin the servo thread to one CPU before the first tick. Refused: start() says so.
  bool pin_cpu = true;
  /// The CPU to pin to; -1: the last CPU this process may run on (CPU 0 takes most of the
  /// interrupts and housekeeping), and only if SCHED_FIFO was granted (a normal thread
  /// pinned to a busy CPU cannot move to an idle one).
  int cpu = -1;
  /// Lock in memory what the loop touches, before the first tick, so that none of it is
  /// paged out (needs root, CAP_IPC_LOCK or a memlock limit that holds it): the servo
  /// thread's stack (kServoStackBytes of it, prefaulted), its record buffer (record_ticks),
  /// the ServoThread object and lock_ranges. The rest of the process is not locked (no
  /// mlockall): loads dropped since, the undo history and the GPU heaps stay pageable and
  /// freed memory returns to the system (MADV_DONTNEED keeps working). Released by stop().
  bool lock_memory = true;
  /// More that each tick touches, locked with the rest by lock_memory (the observer's
  /// queues, a renderer's state): [data, data + bytes). Must stay mapped until stop().
  std::vector<MemoryRange> lock_ranges;
  /// The last part of each wait is spun, not slept [us]; at most max_spin_fraction of T.
  double spin_us = 150;
  /// A thread that never sleeps is throttled under SCHED_FIFO (sched_rt_runtime_us) and
  /// starves the engine thread on small machines: spin at most this fraction of T. 0.5:
  /// on a 2-vCPU VM under compile load, a 10 kHz FIFO loop had p99.9 period errors of
  /// 34-71 us with 0.3 and 19-27 us with 0.5 (0.8 no better); it costs half a CPU at 10 kHz.
  double max_spin_fraction = 0.5;
  /// A device that says when its next input is due (HapticDeviceIO::input_phase: a link
  /// waiting for the answer) gets its ticks moved to input_lead_us after each arrival, at
  /// most 1/16 period a tick (input_phase.h): its round trip is the lead and the tick, not
  /// 0 to 1 period by the clocks' luck. The lead covers the arrivals' jitter; a tick whose
  /// input runs later than the lead waits for it (sleeping in short slices, up to half a
  /// period past the deadline: input_wait_until) rather than leave it to be overtaken by the next one.
  bool follow_input_phase = true;
  double input_lead_us = 100;
  std::size_t record_ticks = 0;   ///< period errors kept (preallocated, prefaulted) for statistics
  WorkspaceTransform world_T_device;
  /// Called once on the servo thread after the real-time setup, right before the first
  /// tick (tests mark the thread here to count its allocations).
  std::function<void()> on_thread_start;
  /// Sees every tick with a published snapshot (null: none). Not owned; must outlive the thread.
  TickObserver* observer = nullptr;
  /// A report older than this at the start of a tick is stale: zero force that tick [s].
  /// 0: the device's DeviceCaps::stale_timeout_s, or two servo periods where that is 0.
  /// Synchronous devices (DeviceReading::received_ns == 0) are never stale.
  double stale_timeout_s = 0;
  /// After the force is enabled (start()) and whenever the device comes back (ok again after
  /// a disconnect, a fault, a refused report, stale reports for longer than stale_restart_s,
  /// a reconnection, or a pause) the force is scaled from 0 to 1 linearly over this time and
  /// the renderer starts afresh, so a HIP inside the object gives no jolt [s].
  double ramp_in_s = 0.05;
  /// Stale ticks for up to this long (a late report or two) give zero force on those ticks
  /// but keep the renderer's contact state and the force level when reports resume [s].
  double stale_restart_s = 0.02;
  /// stop() waits this long for a renderer that does not return, then abandons the thread
  /// with the force off and returns an error [s].
  double stop_timeout_s = 0.5;
  /// The scene's force limit [N]: the gate clamps |F| to min(this, DeviceCaps::max_force_n).
  /// INFINITY: the device's alone.
  double force_limit_n = INFINITY;
  /// The gate's force-rate limit [N/s]; 0: the device's (DeviceCaps::max_force_rate_n_per_s),
  /// else the peak over kDefaultPeakRiseS (force_gate.h).
  double max_force_rate_n_per_s = 0;
  /// The live stage's passivity controller (live_passivity.h): add the damping that keeps
  /// the energy the sent force hands the user at or below what the user put in (one-port,
  /// Hannaford-Ryu). Off: the observer still runs (stats in passivity()).
  bool passivity_control = false;
  /// Its largest added damping [N s/m]; 0: DeviceCaps::max_damping_n_s_per_m where finite,
  /// else kDefaultPassivityAlphaS times the servo rate (0.5 m / T for an 80 g,
  /// Phantom-class end effector: a sampled damper turns active at 2 m / T).
  double passivity_alpha_max_n_s_per_m = 0;
};

/// The default damping cap's mass term [kg]: 0.5 x 0.08 kg (see passivity_alpha_max_n_s_per_m).
inline constexpr double kDefaultPassivityAlphaS = 0.04;

/// Counters of the device side of the servo (ticks unless said otherwise).
struct DeviceCounters {
  long stale = 0;         ///< ticks with no fresh report within the timeout
  long disconnected = 0;  ///< ticks with the link down
  long fault = 0;         ///< ticks the device reported a fault
  /// Ticks the device was not calibrated yet (DeviceStatus::kUncalibrated): zero force, not a
  /// fault (the front ends say "waiting for calibration").
  long uncalibrated = 0;
  long refused = 0;       ///< ticks whose report was refused (non-finite or outside the workspace)
  long ramps = 0;         ///< force ramp-ins started (enable, recovery, reconnection)
  long clamped = 0;       ///< ticks whose force was clamped to the peak (min(scene, device))
  long rate_limited = 0;  ///< ticks whose force change was limited to the gate's rate
  long continuous_limited = 0;  ///< ticks whose |F| was capped at the device's continuous limit
  /// Times the device had taken the force off because the servo did not write for its
  /// stall time (2.5 periods: a late tick, a slow renderer): the force ramped in from 0.
  long late_restarts = 0;
};

/// Fixed-rate loop on CLOCK_MONOTONIC: sleep (clock_nanosleep, absolute, timer slack 1 ns)
/// until spin_us before the deadline, then spin. Before the first tick the thread asks for
/// SCHED_FIFO, pins itself to a CPU, locks memory and prefaults its stack and its record
/// buffer (each optional; what the system refuses is reported by start(), not fatal).
/// Each tick: acquire the newest published samples (lock-free), read the device,
/// Renderer::tick with the measured period dt (the clock read is the loop's, not the
/// tick's: a late tick passes a longer dt, so velocity estimates stay right), write the
/// force. The tick itself allocates nothing, takes no lock and makes no syscall; the stop
/// flag is std::atomic. A tick that starts a whole period late counts as a missed
/// deadline, and the schedule re-anchors on it (no burst of catch-up ticks). After the
/// loop the device is sent an exact zero force.
///
/// Safety, every tick, before the renderer: a reading whose status is not ok, that is older
/// than stale_timeout_s, or that is refused (non-finite or outside the device's workspace
/// box) gives an exact zero force in that same tick and is counted (DeviceCounters); the
/// renderer is not ticked; unless it was a short run of stale ticks (stale_restart_s) it is
/// reset before the next good tick and the force ramps in over ramp_in_s. The ramped force
/// then passes the ForceGate (force_gate.h): |F| clamped to min(force_limit_n,
/// DeviceCaps::max_force_n), capped at the device's continuous limit while its RMS is there,
/// its change limited to the rate limit (also rising from a zero tick), non-finite -> zero.
///
/// Stalls: start() tells the device to take the force off by itself after 2.5 periods
/// without a write (HapticDeviceIO::enable_force). A device that does (one with its own
/// writer thread) counts it; each tick the servo reads that count (an atomic load), and a
/// change (a late tick, a slow renderer) is a restart: that tick's force is zero and the
/// force ramps in from 0 over ramp_in_s (counted: late_restarts).
class ServoThread {
 public:
  /// @throws std::invalid_argument naming rate_hz unless it is in (0, 1e6] Hz.
  ServoThread(TripleBuffer<SampleField>& samples, Renderer& renderer, HapticDeviceIO& device,
              ServoThreadConfig config);
  ~ServoThread();
  ServoThread(const ServoThread&) = delete;
  ServoThread& operator=(const ServoThread&) = delete;

  /// Start the thread, wait until its real-time setup is done (before the first tick), and
  /// return "" or one line per thing the system did not allow (SCHED_FIFO, pinning, memory
  /// locking), each with the reason; those are not fatal, the loop runs anyway.
  /// @throws std::invalid_argument (nothing started, the force left off) when rate_hz is
  ///         above the device's DeviceCaps::output_rate_hz.
  std::string start();
  /// Ask the loop to stop and join it: "", and the device's last force is an exact zero.
  /// A thread still inside Renderer::tick after stop_timeout_s is abandoned instead: the
  /// force is turned off (enable_force(false); a device with its own writer had taken it
  /// off 2.5 periods after the last write), the thread is detached, and the error is
  /// returned. If that renderer ever returns, the thread ends at once without touching this
  /// object, the device, the observer or the renderer again; the renderer, its field and
  /// the device must then still exist (the caller keeps them or ends the process).
  /// @throws nothing; start() after an abandoned thread throws std::logic_error.
  std::string stop();
  /// A stop() abandoned a thread stuck in the renderer (see stop()).
  bool abandoned() const { return abandoned_; }
  /// Paused: every tick sends an exact zero force and the renderer is not ticked (its
  /// contact state is reset on resume, so a resumed probe inside the object is not pulled
  /// out through the plane it held before). Any thread.
  void pause(bool paused) { paused_.store(paused, std::memory_order_relaxed); }
  bool paused() const { return paused_.load(std::memory_order_relaxed); }

  long ticks() const { return ticks_.load(std::memory_order_relaxed); }
  long missed_deadlines() const { return missed_.load(std::memory_order_relaxed); }
  long faults() const { return faults_.load(std::memory_order_relaxed); }
  long snapshot_changes() const { return snapshot_changes_.load(std::memory_order_relaxed); }
  long empty_ticks() const { return empty_.load(std::memory_order_relaxed); }
  /// Ticks that waited past their deadline for a late input (input_wait_until).
  long input_waits() const { return input_waits_.load(std::memory_order_relaxed); }
  /// Of those, the waits that ended without the input (half a period past the deadline).
  long input_wait_timeouts() const { return input_wait_timeouts_.load(std::memory_order_relaxed); }
  /// The device side's counters (any thread; consistent per counter).
  DeviceCounters device_counters() const;
  /// The live stage's passivity observer and controller so far (any thread).
  PassivityStats passivity() const { return passivity_.stats(); }
  /// The status the last tick judged (any thread).
  DeviceStatus device_status() const { return DeviceStatus(status_.load(std::memory_order_relaxed)); }
  /// What the real-time setup got (valid after start()).
  bool got_fifo() const { return got_fifo_; }
  int pinned_cpu() const { return pinned_cpu_; }  ///< -1: not pinned
  bool memory_locked() const { return got_lock_; }  ///< the last start() locked memory
  /// What the last start() locked, whole pages [bytes] (0: nothing).
  std::size_t locked_bytes() const { return locked_bytes_; }
  /// Actual period minus nominal period [ns], one per tick after the first (up to
  /// record_ticks). Read after stop().
  const std::vector<std::int64_t>& period_errors_ns() const { return period_err_; }

 private:
  /// What the servo thread and stop() share; owned by both, so an abandoned thread never
  /// touches this object.
  struct Handoff {
    std::atomic<int> state{0};  // kOutside, kInRenderer, kAbandoned
    std::atomic<bool> done{false};
  };
  void loop(Handoff& h);
  bool wait_done(const Handoff& h) const;
  std::string setup_realtime();
  std::string lock_servo_memory();
  void unlock_servo_memory();
  void count_not_ok(DeviceStatus s, bool refused);
  // Before a tick: waits (sleeping in 20 us slices) for a late input the tick was placed after; the time now.
  std::int64_t wait_for_input(std::int64_t t, std::int64_t next, std::int64_t period);
  TripleBuffer<SampleField>& samples_;
  Renderer& renderer_;
  HapticDeviceIO& device_;
  ServoThreadConfig cfg_;
  std::vector<std::int64_t> period_err_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> ready_{false};
  std::atomic<bool> paused_{false};
  std::string setup_note_;  // written by the servo thread before ready_, read after
  bool got_fifo_ = false, got_lock_ = false;
  std::vector<MemoryRange> locked_;  // page-aligned ranges locked now (released by stop())
  std::size_t locked_bytes_ = 0;
  int pinned_cpu_ = -1;
  std::atomic<long> ticks_{0}, missed_{0}, faults_{0}, snapshot_changes_{0}, empty_{0}, input_waits_{0},
      input_wait_timeouts_{0};
  std::atomic<long> stale_{0}, disconnected_{0}, dev_fault_{0}, uncalibrated_{0}, refused_{0}, ramps_{0}, clamped_{0},
      late_{0};
  std::atomic<std::uint8_t> status_{0};
  DeviceCaps caps_;  // read once at start()
  ForceGate gate_;   // set by start(); servo thread after it
  LivePassivity passivity_;  // set by start(); servo thread after it (stats: any thread)
  std::atomic<long> rate_limited_{0}, continuous_limited_{0};
  std::shared_ptr<Handoff> handoff_;
  bool abandoned_ = false;  // a thread was left stuck in the renderer
  // The device's count of times it took the force off because writes stopped (null: it
  // keeps the last force), and its value the servo last acted on.
  const std::atomic<std::uint64_t>* device_stalls_ = nullptr;
  std::uint64_t seen_stalls_ = 0;  // servo thread (set by start() before it)
  std::thread thread_;
};

}  // namespace isotouch::servo
