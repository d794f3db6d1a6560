// The last zero a link's peer gets however the process ends (servo/exit_zero.h), on a socket
// pair: what the peer's end of the socket received is the truth.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstring>
#include <string>
#include <thread>

#include "isotouch/servo/exit_zero.h"

using isotouch::servo::ExitZero;
using isotouch::servo::send_exit_zeros;

namespace {
/// What is waiting on `fd` now (non-blocking).
std::string pending(int fd) {
  char buf[512];
  const ssize_t n = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
  return n > 0 ? std::string(buf, std::size_t(n)) : std::string();
}
}  // namespace

// One process, in order (the seal is for the life of the process): a link inside a send of
// its own gets no zero in the middle of it (skipped after the wait); the next call sends the
// zero, exactly its bytes; after it the links send nothing of their own (begin_send false).
TEST(ExitZero, TheZeroGoesOutWholeNeverInsideASendAndNothingAfterIt) {
  int a[2], b[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, a), 0);
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, b), 0);
  const std::uint8_t zero_a[] = "ZERO-A", zero_b[] = "ZERO-B";
  ExitZero la(a[0], zero_a, sizeof zero_a - 1), lb(b[0], zero_b, sizeof zero_b - 1);
  ASSERT_TRUE(la.registered() && lb.registered());
  const std::uint8_t too_long[ExitZero::kMaxBytes + 1] = {};
  EXPECT_FALSE(ExitZero(a[0], too_long, sizeof too_long).registered());

  ASSERT_TRUE(la.begin_send());  // link a is inside a send of its own
  EXPECT_EQ(send_exit_zeros(2000), 1) << "only b's zero: a is mid-send";
  EXPECT_EQ(pending(a[1]), "");
  EXPECT_EQ(pending(b[1]), "ZERO-B");
  la.end_send();
  EXPECT_FALSE(lb.begin_send()) << "a link sent after the last zero";
  EXPECT_FALSE(la.begin_send());
  EXPECT_EQ(send_exit_zeros(2000), 2);
  EXPECT_EQ(pending(a[1]), "ZERO-A");
  for (int fd : {a[0], a[1], b[0], b[1]}) close(fd);
}

namespace {
volatile bool g_deeper = true;  // never cleared: the recursion ends in the overflow
/// Recurses until the thread's stack is gone (a frame of 1 KiB that the compiler cannot drop).
[[gnu::noinline]] int overflow(int depth) {
  volatile char pad[1024];
  pad[0] = char(depth);
  return g_deeper ? overflow(depth + 1) + pad[0] : pad[0];
}
}  // namespace

// A thread that overflows its stack (SIGSEGV with no stack left to run a handler on) still
// leaves the peer its zero: the thread has an alternate signal stack (ensure_signal_stack,
// as the servo and link threads do) and the handler runs on it. Then the process dies of
// the signal, as before.
TEST(ExitZero, AStackOverflowStillSendsTheZero) {
#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "a sanitizer owns the overflow's SIGSEGV (and TSan's die_after_fork)";
#endif
  int p[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, p), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    struct rlimit none {0, 0};
    setrlimit(RLIMIT_CORE, &none);  // no core file
    const std::uint8_t zero[] = "ZERO";
    ExitZero link(p[0], zero, sizeof zero - 1);
    std::thread t([] {
      isotouch::servo::ensure_signal_stack();
      overflow(0);
    });
    t.join();
    std::_Exit(3);  // never reached
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGSEGV) << "status " << status;
  EXPECT_EQ(pending(p[1]), "ZERO") << "the overflow left the peer no zero";
}
