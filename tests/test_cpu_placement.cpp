// Keeping a peer process off a CPU: a child process with two threads, at the other end of a
// Unix socket, is moved off one CPU and given its own sets back; the truth is the kernel's
// own view of each thread's CPU set (sched_getaffinity), read by the test.
#include <gtest/gtest.h>
#include <sched.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/servo/cpu_placement.h"
#include "isotouch/tests/unprivileged_child.h"

using isotouch::servo::PeerOffCpu;

namespace {
/// A child process that connects to the abstract Unix socket `name` (so that the accepted
/// end names it as the peer, as an X server's listening socket names the server), starts a
/// second thread and blocks reading until the parent closes the connection.
pid_t start_child(const sockaddr_un& addr, socklen_t len) {
  const pid_t pid = fork();
  if (pid != 0) return pid;
  const int fd = socket(AF_UNIX, SOCK_STREAM, 0);
  if (fd < 0 || connect(fd, reinterpret_cast<const sockaddr*>(&addr), len) != 0) _exit(2);
  std::thread t([fd] {
    char c;
    while (read(fd, &c, 1) > 0) {
    }
  });
  const char ready = 'r';
  if (write(fd, &ready, 1) != 1) _exit(2);
  t.join();
  _exit(0);
}

std::vector<pid_t> threads_of(pid_t pid) {
  std::vector<pid_t> out;
  for (const auto& e : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/task"))
    out.push_back(pid_t(std::stol(e.path().filename().string())));
  return out;
}

bool on_cpu(pid_t tid, int cpu) {
  cpu_set_t s;
  EXPECT_EQ(sched_getaffinity(tid, sizeof(s), &s), 0);
  return CPU_ISSET(cpu, &s);
}

struct Child {
  int fd = -1;  // the parent's end of the connection
  pid_t pid = -1;
  Child() {
    const int listener = socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    const std::string name = "isotouch-test-cpu-placement-" + std::to_string(getpid());
    std::memcpy(addr.sun_path + 1, name.data(), name.size());  // abstract: sun_path[0] = 0
    const auto len = socklen_t(offsetof(sockaddr_un, sun_path) + 1 + name.size());
    EXPECT_EQ(bind(listener, reinterpret_cast<sockaddr*>(&addr), len), 0);
    EXPECT_EQ(listen(listener, 1), 0);
    pid = start_child(addr, len);
    fd = accept(listener, nullptr, nullptr);
    close(listener);
    char c = 0;
    EXPECT_EQ(read(fd, &c, 1), 1);  // its second thread runs
  }
  ~Child() {
    close(fd);
    int st = 0;
    waitpid(pid, &st, 0);
  }
};
}  // namespace

TEST(CpuPlacement, ThePeerOfASocketLeavesTheCpuAndGetsItsSetsBack) {
  cpu_set_t mine;
  ASSERT_EQ(sched_getaffinity(0, sizeof(mine), &mine), 0);
  if (CPU_COUNT(&mine) < 2) GTEST_SKIP() << "needs two CPUs";
  int cpu = CPU_SETSIZE - 1;
  while (!CPU_ISSET(cpu, &mine)) --cpu;
  Child child;
  const std::vector<pid_t> tids = threads_of(child.pid);
  ASSERT_GE(tids.size(), 2u);  // its two (a sanitizer's runtime may add its own)
  for (pid_t t : tids) ASSERT_TRUE(on_cpu(t, cpu));
  {
    PeerOffCpu off;
    std::string why;
    const pid_t peer = isotouch::servo::peer_pid(child.fd, why);
    EXPECT_EQ(peer, child.pid) << why;
    ASSERT_EQ(off.keep_off(peer, cpu), "");
    EXPECT_EQ(off.pid(), child.pid);
    EXPECT_GE(off.threads_moved(), 2);
    for (pid_t t : tids) EXPECT_FALSE(on_cpu(t, cpu)) << "thread " << t;
  }
  for (pid_t t : tids) EXPECT_TRUE(on_cpu(t, cpu)) << "thread " << t << " not given its set back";
}

namespace {
int last_cpu_of(const cpu_set_t& set) {
  int cpu = CPU_SETSIZE - 1;
  while (cpu > 0 && !CPU_ISSET(cpu, &set)) --cpu;
  return cpu;
}

/// Whether process `pid` is gone or a zombie (an orphan waits for its reaper).
bool ended(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(f, stat)) return true;
  const auto close = stat.rfind(')');
  return close != std::string::npos && close + 2 < stat.size() && stat[close + 2] == 'Z';
}
}  // namespace

// The process that moved the threads is killed with SIGKILL (nothing of it runs): the guard
// it started gives the stand-in's threads their sets back; the truth is the kernel's view
// of each thread's set, read by this test.
TEST(CpuPlacement, TheThreadsGetTheirSetsBackWhenTheMoverIsKilled) {
  cpu_set_t mine;
  ASSERT_EQ(sched_getaffinity(0, sizeof(mine), &mine), 0);
  if (CPU_COUNT(&mine) < 2) GTEST_SKIP() << "needs two CPUs";
  const int cpu = last_cpu_of(mine);
  Child standin;
  const std::vector<pid_t> tids = threads_of(standin.pid);
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const pid_t mover = fork();
  if (mover == 0) {  // the app's side: its guard first (as before a servo starts), then the move
    PeerOffCpu off;
    const pid_t early = off.start_guard().empty() ? off.guard_pid() : -1;
    const bool moved = off.keep_off(standin.pid, cpu).empty() && off.threads_moved() > 0;
    const pid_t guard = moved && off.guard_pid() == early ? early : -1;
    if (write(ready[1], &guard, sizeof(guard)) != sizeof(guard)) _exit(2);
    for (;;) pause();
  }
  close(ready[1]);
  pid_t guard = -1;
  ASSERT_EQ(read(ready[0], &guard, sizeof(guard)), ssize_t(sizeof(guard)));
  close(ready[0]);
  for (pid_t t : tids) EXPECT_FALSE(on_cpu(t, cpu)) << "thread " << t << " not moved";
  ASSERT_EQ(kill(mover, SIGKILL), 0);
  int st = 0;
  ASSERT_EQ(waitpid(mover, &st, 0), mover);
  ASSERT_TRUE(WIFSIGNALED(st));
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  auto all_back = [&] {
    for (pid_t t : tids)
      if (!on_cpu(t, cpu)) return false;
    return true;
  };
  while (!all_back() && std::chrono::steady_clock::now() < until) usleep(2000);
  for (pid_t t : tids) EXPECT_TRUE(on_cpu(t, cpu)) << "thread " << t << " still kept off CPU " << cpu;
  ASSERT_GT(guard, 0);
  while (!ended(guard) && std::chrono::steady_clock::now() < until) usleep(2000);
  EXPECT_TRUE(ended(guard)) << "the guard " << guard << " outlived its work";
}

// A clean end gives the sets back itself and ends the guard (no process left behind).
TEST(CpuPlacement, TheGuardEndsWithTheObject) {
  cpu_set_t mine;
  ASSERT_EQ(sched_getaffinity(0, sizeof(mine), &mine), 0);
  if (CPU_COUNT(&mine) < 2) GTEST_SKIP() << "needs two CPUs";
  Child standin;
  pid_t guard = -1;
  {
    PeerOffCpu off;
    ASSERT_EQ(off.keep_off(standin.pid, last_cpu_of(mine)), "");
    guard = off.guard_pid();
    ASSERT_GT(guard, 0);
    EXPECT_FALSE(ended(guard));
  }
  EXPECT_EQ(kill(guard, 0), -1) << "guard " << guard << " left running or unreaped";
}

TEST(CpuPlacement, AThreadWithNoOtherCpuStaysWhereItIs) {
  cpu_set_t mine;
  ASSERT_EQ(sched_getaffinity(0, sizeof(mine), &mine), 0);
  int cpu = 0;
  while (!CPU_ISSET(cpu, &mine)) ++cpu;
  Child child;
  cpu_set_t only;
  CPU_ZERO(&only);
  CPU_SET(cpu, &only);
  for (pid_t t : threads_of(child.pid)) ASSERT_EQ(sched_setaffinity(t, sizeof(only), &only), 0);
  PeerOffCpu off;
  EXPECT_EQ(off.keep_off(child.pid, cpu), "");
  EXPECT_EQ(off.threads_moved(), 0);
  for (pid_t t : threads_of(child.pid)) EXPECT_TRUE(on_cpu(t, cpu));
}

TEST(CpuPlacement, NoSuchProcessOrCpuIsNamed) {
  PeerOffCpu off;
  const std::string e = off.keep_off(999999999, 0);
  EXPECT_NE(e.find("process 999999999"), std::string::npos) << e;
  EXPECT_NE(off.keep_off(getpid(), -1).find("CPU -1"), std::string::npos);
  std::string why;
  EXPECT_EQ(isotouch::servo::peer_pid(-1, why), -1);
  EXPECT_NE(why.find("no local process"), std::string::npos) << why;
}

// Only an X server is moved: under Xwayland the display socket's owner may be the Wayland
// compositor itself.
TEST(CpuPlacement, OnlyAnXServerIsNamedOne) {
  for (const char* x : {"Xorg", "Xvfb", "Xwayland", "Xephyr", "Xvnc"}) EXPECT_TRUE(isotouch::servo::is_x_server(x)) << x;
  for (const char* other : {"gnome-shell", "kwin_wayland", "mutter", "xfwm4", ""})
    EXPECT_FALSE(isotouch::servo::is_x_server(other)) << other;
}

// The calling thread's own placement: the kernel's view of the thread (sched_getscheduler,
// sched_getaffinity on tid 0) inside and after a ScopedRealtime.
namespace {
struct ThreadSched {
  int policy = -1;
  int priority = -1;
  cpu_set_t set{};
};
ThreadSched thread_sched() {
  ThreadSched t;
  t.policy = sched_getscheduler(0);
  sched_param sp{};
  if (sched_getparam(0, &sp) == 0) t.priority = sp.sched_priority;
  CPU_ZERO(&t.set);
  sched_getaffinity(0, sizeof(t.set), &t.set);
  return t;
}
/// Whether this process may ask for SCHED_FIFO: CAP_SYS_NICE (bit 23) in its effective
/// capabilities (root in a container can lack it).
bool has_cap_sys_nice() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("CapEff:", 0) == 0) return (std::stoull(line.substr(7), nullptr, 16) >> 23) & 1;
  return false;
}
}  // namespace

TEST(CpuPlacement, ScopedRealtimeGivesTheThreadItsSchedulingBack) {
  std::thread([] {
    // From SCHED_BATCH (any thread may take it), so that a restore to the default policy
    // instead of the thread's own shows.
    const sched_param zero{};
    ASSERT_EQ(sched_setscheduler(0, SCHED_BATCH, &zero), 0);
    const ThreadSched before = thread_sched();
    ASSERT_EQ(before.policy, SCHED_BATCH);
    int highest = -1;
    for (int c = 0; c < CPU_SETSIZE; ++c)
      if (CPU_ISSET(c, &before.set)) highest = c;
    {
      const isotouch::servo::ScopedRealtime rt("test thread");
      const ThreadSched in = thread_sched();
      if (has_cap_sys_nice()) {
        EXPECT_TRUE(rt.setup().fifo) << rt.setup().note;  // CI runs as root
      }
      if (rt.setup().fifo) {
        EXPECT_EQ(in.policy, SCHED_FIFO);
        EXPECT_EQ(in.priority, 80);
        EXPECT_EQ(rt.setup().cpu, highest);  // the last CPU the thread was allowed
        EXPECT_EQ(CPU_COUNT(&in.set), 1);
        EXPECT_TRUE(CPU_ISSET(highest, &in.set));
      } else {
        EXPECT_EQ(in.policy, before.policy);
        EXPECT_NE(rt.setup().note.find("test thread: SCHED_FIFO priority 80 refused"), std::string::npos)
            << rt.setup().note;
      }
    }
    const ThreadSched after = thread_sched();
    EXPECT_EQ(after.policy, before.policy);
    EXPECT_EQ(after.priority, before.priority);
    EXPECT_TRUE(CPU_EQUAL(&after.set, &before.set));
  }).join();
}

TEST(CpuPlacement, ARefusedSchedFifoIsNamedAndNothingIsPinned) {
  if (geteuid() != 0) GTEST_SKIP() << "needs root to drop to an unprivileged user";
  // A child that gives up root (and with it CAP_SYS_NICE) asks for SCHED_FIFO: refused,
  // named in the note, not pinned, its scheduling as it was. Exit code: the first failed check.
  const int code = isotouch::test::run_unprivileged([] {
    const ThreadSched before = thread_sched();
    int fail = 0;
    {
      const isotouch::servo::ScopedRealtime rt("bench");
      const ThreadSched in = thread_sched();
      const std::string& note = rt.setup().note;
      if (rt.setup().fifo) fail = 1;
      else if (rt.setup().cpu != -1) fail = 2;
      else if (note.find("bench: SCHED_FIFO priority 80 refused") == std::string::npos) fail = 3;
      else if (note.find("bench: not pinned") == std::string::npos) fail = 4;
      else if (in.policy != before.policy || !CPU_EQUAL(&in.set, &before.set)) fail = 5;
    }
    return fail;
  });
  if (code == isotouch::test::kCouldNotDrop) GTEST_SKIP() << "could not drop to uid 65534 (a user namespace without it?)";
  EXPECT_EQ(code, 0) << "1: FIFO granted, 2: pinned, 3/4: the note, 5: scheduling changed, 11: threw, -1: crashed";
}

// ScopedOffCpu: the calling thread's CPU set without the CPU (as the kernel reports it)
// while it lives, the whole set again after; a thread with no other CPU, or CPU -1, stays.
TEST(CpuPlacement, ScopedOffCpuKeepsTheThreadOffAndGivesTheSetBack) {
  cpu_set_t mine;
  ASSERT_EQ(sched_getaffinity(0, sizeof(mine), &mine), 0);
  int cpu = 0;
  while (!CPU_ISSET(cpu, &mine)) ++cpu;
  std::thread t([&] {
    {
      const isotouch::servo::ScopedOffCpu off(cpu);
      cpu_set_t now;
      ASSERT_EQ(sched_getaffinity(0, sizeof(now), &now), 0);
      if (CPU_COUNT(&mine) >= 2) {
        EXPECT_TRUE(off.moved());
        EXPECT_FALSE(CPU_ISSET(cpu, &now)) << "still allowed on CPU " << cpu;
        EXPECT_EQ(CPU_COUNT(&now), CPU_COUNT(&mine) - 1);
      } else {
        EXPECT_FALSE(off.moved());
      }
    }
    cpu_set_t after;
    ASSERT_EQ(sched_getaffinity(0, sizeof(after), &after), 0);
    EXPECT_TRUE(CPU_EQUAL(&after, &mine)) << "the set was not given back";
    // Only that CPU: nothing moves. CPU -1: nothing moves.
    cpu_set_t only;
    CPU_ZERO(&only);
    CPU_SET(cpu, &only);
    ASSERT_EQ(sched_setaffinity(0, sizeof(only), &only), 0);
    EXPECT_FALSE(isotouch::servo::ScopedOffCpu(cpu).moved());
    EXPECT_FALSE(isotouch::servo::ScopedOffCpu(-1).moved());
    cpu_set_t still;
    ASSERT_EQ(sched_getaffinity(0, sizeof(still), &still), 0);
    EXPECT_TRUE(CPU_EQUAL(&still, &only));
  });
  t.join();
}
