// The scheduling canary that widens the wall-clock safety tests' bounds (sched_canary.h): it
// must see the time a process could not run, and only within the window asked about. Truth
// from outside it: the process is stopped with SIGSTOP for a known time by its parent, as a VM
// that loses its CPUs stops everything in it.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <thread>

#include "isotouch/tests/sched_canary.h"

using isotouch::test::SchedCanary;

namespace {
constexpr std::int64_t kStopNs = 40'000'000;  // how long the parent stops the child
constexpr std::int64_t kPeriodNs = 100'000;   // the canaries' (SchedCanary's default)

struct Seen {
  std::int64_t in_stop, second_half, outside, canaries, fifo;
};

/// In a child: canaries, then the parent stops this process for kStopNs and sends when
/// (a, b); what the canaries saw over [a, b], its second half, and the rest of the window.
void child(int ready_fd, int times_fd, int result_fd) {
  SchedCanary canary;
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const std::int64_t t0 = SchedCanary::now_ns();
  char go = 1;
  (void)!write(ready_fd, &go, 1);
  std::int64_t ab[2] = {};
  if (read(times_fd, ab, sizeof ab) != ssize_t(sizeof ab)) _exit(1);
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  const std::int64_t t1 = SchedCanary::now_ns();
  canary.stop();
  const auto [a, b] = ab;
  const Seen seen{canary.lost_ns(a, b), canary.lost_ns((a + b) / 2, b),
                  canary.lost_ns(t0, a - 1'000'000) + canary.lost_ns(b + 1'000'000, t1), canary.canaries(),
                  canary.all_fifo()};
  (void)!write(result_fd, &seen, sizeof seen);
}
}  // namespace

TEST(SchedCanary, SeesTheTimeTheProcessWasStoppedAndOnlyInsideTheWindow) {
  int ready[2], times[2], result[2];
  ASSERT_EQ(pipe(ready), 0);
  ASSERT_EQ(pipe(times), 0);
  ASSERT_EQ(pipe(result), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    child(ready[1], times[0], result[1]);
    _exit(0);
  }
  char go = 0;
  ASSERT_EQ(read(ready[0], &go, 1), 1);
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  const std::int64_t a = SchedCanary::now_ns();
  kill(pid, SIGSTOP);
  // The child stops once the signal is delivered (later on a loaded machine): from when the
  // kernel says it has stopped, every canary is surely stopped.
  int stopped = 0;
  ASSERT_EQ(waitpid(pid, &stopped, WUNTRACED), pid);
  ASSERT_TRUE(WIFSTOPPED(stopped));
  const std::int64_t a_stopped = SchedCanary::now_ns();
  std::this_thread::sleep_for(std::chrono::nanoseconds(kStopNs));
  const std::int64_t b = SchedCanary::now_ns();
  kill(pid, SIGCONT);
  const std::int64_t ab[2] = {a, b};
  ASSERT_EQ(write(times[1], ab, sizeof ab), ssize_t(sizeof ab));
  Seen seen{};
  ASSERT_EQ(read(result[0], &seen, sizeof seen), ssize_t(sizeof seen));
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_GE(seen.canaries, 1);
  // Every canary was stopped from a_stopped to b (and until SIGCONT), less up to one period
  // before its next deadline; no window holds more than its length on each canary.
  EXPECT_GE(seen.in_stop, seen.canaries * (b - a_stopped - kPeriodNs)) << "the canaries missed the stop";
  EXPECT_LE(seen.in_stop, seen.canaries * (b - a));
  EXPECT_LE(seen.second_half, seen.canaries * (b - (a + b) / 2)) << "a lost interval counted past the window";
  EXPECT_GE(seen.second_half, seen.canaries * (b - (a + b) / 2 - kPeriodNs));
  // Outside the stop (1 ms apart) the machine's own losses only (a VM loses its CPU for ms
  // now and then): far below what the stop was on every canary.
  EXPECT_LT(seen.outside, seen.canaries * kStopNs / 2) << "the stop was counted outside its window";
  std::printf("stopped %.1f ms: %ld canaries (%s) saw %.1f ms in it, %.2f ms outside it\n",
              double(b - a) * 1e-6, long(seen.canaries), seen.fifo ? "SCHED_FIFO" : "normal priority",
              double(seen.in_stop) * 1e-6, double(seen.outside) * 1e-6);
}
