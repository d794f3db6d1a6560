// Keeping a peer process off a CPU: a child process with two threads, at the other end of a
// Unix socket, is moved off one CPU and given its own sets back; the truth is the kernel's
// own view of each thread's CPU set (sched_getaffinity), read by the test.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstddef>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "cpu_placement.h"

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
