// sched_canary.h - how long the machine was gone, measured beside a wall-clock safety test.
//
// A test that bounds a wall-clock interval (the zero within 3 servo periods of the last force)
// cannot tell a late zero from a VM that lost its CPU for 2 ms in that window. One canary
// thread per CPU the test may use, pinned there at the highest SCHED_FIFO priority (where
// allowed), wakes every `period` at absolute deadlines; each wake-up later than `slack` marks
// the interval [deadline, wake-up] on that CPU as lost: nothing of the test's could have run
// there. A test widens its bound by lost_ns() over the interval it bounds, and by nothing
// else: on a quiet machine the canaries see ~0 and the bound is the product's.
#pragma once
#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/servo/cpu_placement.h"

namespace isotouch::test {

class SchedCanary {
 public:
  /// Starts one canary per CPU in this process's affinity mask (at most `max_cpus`). A wake-up
  /// later than `slack_ns` counts whole: the threads a test times wake on the same timers and
  /// are as late (a 2-vCPU VM's wake-ups are 20-50 us late now and then); a loss that began
  /// between two deadlines is seen from the later one, so the period bounds what is missed.
  explicit SchedCanary(std::int64_t period_ns = 100'000, std::int64_t slack_ns = 20'000, int max_cpus = 8)
      : period_ns_(period_ns), slack_ns_(slack_ns) {
    cpu_set_t set;
    CPU_ZERO(&set);
    sched_getaffinity(0, sizeof set, &set);
    for (int cpu = 0; cpu < CPU_SETSIZE && int(cpus_.size()) < max_cpus; ++cpu)
      if (CPU_ISSET(cpu, &set)) cpus_.push_back(std::make_unique<Cpu>(cpu));
    for (auto& c : cpus_) c->thread = std::thread([this, p = c.get()] { watch(*p); });
  }
  ~SchedCanary() { stop(); }
  SchedCanary(const SchedCanary&) = delete;
  SchedCanary& operator=(const SchedCanary&) = delete;

  void stop() {
    stop_.store(true);
    for (auto& c : cpus_)
      if (c->thread.joinable()) c->thread.join();
  }

  /// CLOCK_MONOTONIC [ns], the clock the canaries and the tests' timestamps use.
  static std::int64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::int64_t(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec;
  }

  /// Time lost inside [from_ns, to_ns] [ns]: per CPU, the lost intervals' overlap with the
  /// window, summed over the CPUs (a chain of threads on two CPUs can be held up by both).
  std::int64_t lost_ns(std::int64_t from_ns, std::int64_t to_ns) const {
    std::int64_t sum = 0;
    for (const auto& c : cpus_) {
      std::lock_guard lock(c->mu);
      for (const auto& [a, b] : c->lost) sum += std::max<std::int64_t>(0, std::min(b, to_ns) - std::max(a, from_ns));
    }
    return sum;
  }

  /// One line for a failure message: the lost time in the window and how the canaries ran.
  std::string describe(std::int64_t from_ns, std::int64_t to_ns) const {
    std::string s = "the canaries saw " + std::to_string(lost_ns(from_ns, to_ns) / 1000) + " us lost in the " +
                    std::to_string((to_ns - from_ns) / 1000) + " us window (";
    for (const auto& c : cpus_) {
      std::lock_guard lock(c->mu);
      s += "cpu " + std::to_string(c->cpu) + (c->fifo ? " fifo" : " normal") + " " + std::to_string(c->wakes) +
           " wakes; ";
    }
    return s + "period " + std::to_string(period_ns_ / 1000) + " us)";
  }

  /// How many canaries run (one per CPU of the affinity mask, at most `max_cpus`).
  std::int64_t canaries() const { return std::int64_t(cpus_.size()); }

  /// Whether every canary runs at SCHED_FIFO (else they see the scheduler's delays too,
  /// which also widens the bound: still the test's own measured scheduling).
  bool all_fifo() const {
    for (const auto& c : cpus_)
      if (!c->fifo) return false;
    return !cpus_.empty();
  }

 private:
  struct Cpu {
    explicit Cpu(int c) : cpu(c) {}
    int cpu;
    bool fifo = false;
    long wakes = 0;
    std::thread thread;
    mutable std::mutex mu;  // taken by the canary only when it records a lost interval
    std::vector<std::pair<std::int64_t, std::int64_t>> lost;
  };

  void watch(Cpu& c) {
    const servo::RealtimeSetup rt = servo::make_thread_realtime("sched canary", true, 99, true, c.cpu);
    {
      std::lock_guard lock(c.mu);
      c.fifo = rt.fifo;
    }
    std::int64_t next = now_ns();
    while (!stop_.load(std::memory_order_relaxed)) {
      next += period_ns_;
      const timespec ts{time_t(next / 1'000'000'000LL), long(next % 1'000'000'000LL)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) != 0) {
      }
      const std::int64_t woke = now_ns();
      std::lock_guard lock(c.mu);
      ++c.wakes;
      if (woke - next > slack_ns_) {
        c.lost.emplace_back(next, woke);
        next = woke;  // the next deadline a period from now, not a burst of catch-up wakes
      }
    }
  }

  std::int64_t period_ns_, slack_ns_;
  std::atomic<bool> stop_{false};
  std::vector<std::unique_ptr<Cpu>> cpus_;
};

}  // namespace isotouch::test
