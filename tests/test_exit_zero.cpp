// The last zero a link's peer gets however the process ends (servo/exit_zero.h), on a socket
// pair: what the peer's end of the socket received is the truth.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

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
