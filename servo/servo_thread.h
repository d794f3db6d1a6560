// servo_thread.h - the fixed-rate real-time servo thread.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "device_io.h"
#include "hri.h"
#include "triple_buffer.h"
#include "workspace.h"

namespace isotouch::servo {

struct ServoThreadConfig {
  double rate_hz = 1000;          ///< servo rate, 1 to 10 kHz [Hz]
  bool sched_fifo = false;        ///< ask for SCHED_FIFO (needs CAP_SYS_NICE or an rtprio limit)
  int fifo_priority = 80;         ///< SCHED_FIFO priority
  int cpu = -1;                   ///< pin to this CPU; -1: no pinning
  double spin_us = 150;           ///< the last part of each wait is spun, not slept [us]; at most 30 % of T
  std::size_t record_ticks = 0;   ///< period errors kept (preallocated) for statistics
  WorkspaceTransform world_T_device;
  /// Called once on the servo thread before the loop starts (tests mark the thread).
  std::function<void()> on_thread_start;
};

/// Fixed-rate loop on CLOCK_MONOTONIC: sleep (clock_nanosleep, absolute) until spin_us
/// before the deadline, then spin. Each tick: acquire the newest published samples
/// (lock-free), read the device, HriRenderer::tick, write the force. The tick itself
/// allocates nothing, takes no lock and makes no syscall; the stop flag is std::atomic.
/// A tick that starts a whole period late counts as a missed deadline, and the schedule
/// re-anchors on it (no burst of catch-up ticks).
class ServoThread {
 public:
  ServoThread(TripleBuffer<SampleField>& samples, HriRenderer& renderer, HapticDeviceIO& device,
              ServoThreadConfig config);
  ~ServoThread();
  ServoThread(const ServoThread&) = delete;
  ServoThread& operator=(const ServoThread&) = delete;

  /// Start the loop. Returns "" or a note on what the system did not allow (SCHED_FIFO,
  /// pinning); those are not fatal, the loop runs anyway.
  std::string start();
  /// Ask the loop to stop and join it.
  void stop();

  long ticks() const { return ticks_.load(std::memory_order_relaxed); }
  long missed_deadlines() const { return missed_.load(std::memory_order_relaxed); }
  long faults() const { return faults_.load(std::memory_order_relaxed); }
  long snapshot_changes() const { return snapshot_changes_.load(std::memory_order_relaxed); }
  long empty_ticks() const { return empty_.load(std::memory_order_relaxed); }
  /// Actual period minus nominal period [ns], one per tick after the first (up to
  /// record_ticks). Read after stop().
  const std::vector<std::int64_t>& period_errors_ns() const { return period_err_; }

 private:
  void loop();
  TripleBuffer<SampleField>& samples_;
  HriRenderer& renderer_;
  HapticDeviceIO& device_;
  ServoThreadConfig cfg_;
  std::vector<std::int64_t> period_err_;
  std::atomic<bool> stop_{false};
  std::atomic<long> ticks_{0}, missed_{0}, faults_{0}, snapshot_changes_{0}, empty_{0};
  std::thread thread_;
};

}  // namespace isotouch::servo
