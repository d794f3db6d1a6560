// bench_cpu_gaps - the floor of a real-time thread on this machine, beside the servo's own
// figures (isotouch bench servo-rt, isotouch-sculpt --bench): threads pinned one per CPU under
// SCHED_FIFO spin on the monotonic clock and record every gap between two readings longer
// than 0.2 ms. Nothing in the guest can preempt them (they rest 60 ms after every 900 ms of
// spinning, so the kernel's real-time throttling, 950 ms per second by default, never acts;
// the rests are not gaps), so a gap is time the CPU itself did not run them: on a virtual
// machine, the host not running that vCPU. A 1 kHz servo misses a deadline whenever such a
// gap of more than 1 ms falls on its CPU.
//
// Phase 1: every CPU spins (the load of a frame that keeps lavapipe's threads on every
// CPU). Phase 2: only the last CPU spins, the others idle (the servo alone). For phase 1 it
// also counts the gaps of the first CPU longer than 1 ms that another CPU shared for more
// than half of their length (the machine stopped as a whole) and those it did not.
// Usage: bench_cpu_gaps [SECONDS_PER_PHASE]   (needs CAP_SYS_NICE for SCHED_FIFO: root)
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

struct Gap {
  std::int64_t start_ns, end_ns;
};

struct Spinner {
  int cpu = 0;
  std::int64_t until_ns = 0;
  std::vector<Gap> gaps;  // reserved before the start: no allocation while spinning
  std::int64_t spun_ns = 0;
  bool fifo = false, pinned = false;
};

void spin(Spinner& s) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(s.cpu, &set);
  s.pinned = pthread_setaffinity_np(pthread_self(), sizeof set, &set) == 0;
  sched_param sp{};
  sp.sched_priority = 50;
  s.fifo = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
  constexpr std::int64_t kGap = 200'000, kWork = 900'000'000, kRest = 60'000'000;
  std::int64_t prev = now_ns(), work_start = prev;
  while (prev < s.until_ns) {
    const std::int64_t t = now_ns();
    if (t - prev > kGap && s.gaps.size() < s.gaps.capacity()) s.gaps.push_back({prev, t});
    prev = t;
    if (t - work_start > kWork) {  // rest, so that real-time throttling never stops us
      s.spun_ns += t - work_start;
      std::this_thread::sleep_for(std::chrono::nanoseconds(kRest));
      prev = work_start = now_ns();
    }
  }
  s.spun_ns += prev - work_start;
}

void report(const char* phase, const std::vector<Spinner>& sp) {
  for (const Spinner& s : sp) {
    std::int64_t total = 0, longest = 0;
    int over_1ms = 0;
    for (const Gap& g : s.gaps) {
      const std::int64_t d = g.end_ns - g.start_ns;
      total += d;
      longest = std::max(longest, d);
      over_1ms += d > 1'000'000;
    }
    std::printf("%s: CPU %d%s%s: spun %.2f s; %zu gaps > 0.2 ms, %d > 1 ms; lost %.1f ms (%.2f %%), longest %.2f ms\n",
                phase, s.cpu, s.fifo ? ", FIFO" : ", NOT FIFO", s.pinned ? "" : ", NOT PINNED", double(s.spun_ns) * 1e-9,
                s.gaps.size(), over_1ms, double(total) * 1e-6,
                s.spun_ns > 0 ? 100.0 * double(total) / double(s.spun_ns) : 0.0, double(longest) * 1e-6);
  }
}

/// Of the first spinner's gaps over 1 ms: those another spinner shared for more than half.
void report_overlap(const std::vector<Spinner>& sp) {
  if (sp.size() < 2) return;
  int together = 0, alone = 0;
  for (const Gap& g : sp[0].gaps) {
    const std::int64_t d = g.end_ns - g.start_ns;
    if (d <= 1'000'000) continue;
    std::int64_t shared = 0;
    for (std::size_t k = 1; k < sp.size(); ++k)
      for (const Gap& h : sp[k].gaps)
        shared = std::max(shared, std::min(g.end_ns, h.end_ns) - std::max(g.start_ns, h.start_ns));
    (2 * shared > d ? together : alone) += 1;
  }
  std::printf("all CPUs: of CPU %d's gaps > 1 ms, %d also stopped another CPU for more than half their length, "
              "%d did not\n", sp[0].cpu, together, alone);
}

std::vector<Spinner> run_phase(const std::vector<int>& cpus, double seconds) {
  std::vector<Spinner> sp(cpus.size());
  const std::int64_t until = now_ns() + std::int64_t(seconds * 1e9);
  for (std::size_t i = 0; i < cpus.size(); ++i) {
    sp[i].cpu = cpus[i];
    sp[i].until_ns = until;
    sp[i].gaps.reserve(1 << 20);
  }
  std::vector<std::thread> th;
  for (Spinner& s : sp) th.emplace_back(spin, std::ref(s));
  for (std::thread& t : th) t.join();
  return sp;
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 10.0;
  const int n = int(std::thread::hardware_concurrency());
  if (!(seconds > 0) || n < 1) {
    std::fprintf(stderr, "usage: bench_cpu_gaps [SECONDS_PER_PHASE > 0]\n");
    return 2;
  }
  std::printf("bench_cpu_gaps: %d CPUs, %.1f s per phase; gaps = time a pinned SCHED_FIFO spinner did not run\n", n,
              seconds);
  std::vector<int> all(n);
  for (int i = 0; i < n; ++i) all[i] = i;
  const std::vector<Spinner> busy = run_phase(all, seconds);
  report("all CPUs", busy);
  report_overlap(busy);
  const std::vector<Spinner> one = run_phase({n - 1}, seconds);
  report("one CPU ", one);
  const bool rt = std::all_of(busy.begin(), busy.end(), [](const Spinner& s) { return s.fifo && s.pinned; }) &&
                  one[0].fifo && one[0].pinned;
  if (!rt) std::printf("note: not every spinner got SCHED_FIFO and its CPU: gaps include other threads' turns\n");
  return rt ? 0 : 1;
}
