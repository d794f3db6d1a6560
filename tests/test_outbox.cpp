// test_outbox - a client's Outbox (service/outbox.h) on loopback TCP: what the peer receives
// when it reads, and when it does not (the pusher never waits; the client is dropped, its
// connection shut down), and a Connection's quiet time and send deadline.
#include <gtest/gtest.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/outbox.h"

namespace isotouch::service {
namespace {
using Clock = std::chrono::steady_clock;

/// A loopback pair: the server's accepted fd and the peer's connected socket.
struct Pair {
  int server = -1, peer = -1;
  explicit Pair(int peer_rcvbuf = 0) {
    Listener l("127.0.0.1", 0);
    peer = ::socket(AF_INET, SOCK_STREAM, 0);
    if (peer_rcvbuf > 0) ::setsockopt(peer, SOL_SOCKET, SO_RCVBUF, &peer_rcvbuf, sizeof peer_rcvbuf);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(std::uint16_t(l.port()));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(peer, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) ADD_FAILURE() << "connect";
    server = l.accept(1000);
  }
  ~Pair() { ::close(peer); }
};

/// Reads from `fd` until `n` bytes or EOF (or 5 s).
std::vector<std::uint8_t> read_n(int fd, std::size_t n) {
  std::vector<std::uint8_t> got;
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  std::uint8_t b[65536];
  while (got.size() < n) {
    const ssize_t k = ::recv(fd, b, sizeof b, 0);
    if (k <= 0) break;
    got.insert(got.end(), b, b + k);
  }
  return got;
}

TEST(Outbox, AReadingPeerGetsEveryMessageInOrder) {
  Pair p;
  auto conn = std::make_shared<Connection>(p.server, 2000, 60000, nullptr);
  std::atomic<int> drops{0};
  Outbox box(conn, 1 << 20, [&](const std::string&) { ++drops; });
  std::vector<std::uint8_t> want;
  for (int i = 0; i < 100; ++i) {
    std::vector<std::uint8_t> m(1000 + std::size_t(i), std::uint8_t(i));
    want.insert(want.end(), m.begin(), m.end());
    ASSERT_TRUE(box.push(std::move(m)));
  }
  EXPECT_EQ(read_n(p.peer, want.size()), want);
  EXPECT_TRUE(box.flush(2000));
  EXPECT_EQ(box.sent(), 100);
  EXPECT_EQ(drops, 0);
  EXPECT_TRUE(conn->alive());
}

TEST(Outbox, APeerNotReadingIsDroppedAndThePusherNeverWaits) {
  Pair p;
  auto conn = std::make_shared<Connection>(p.server, 2000, 60000, nullptr);
  std::atomic<int> drops{0};
  std::string why;
  Outbox box(conn, 4 << 20, [&](const std::string& w) { why = w, ++drops; });
  const std::vector<std::uint8_t> chunk(1 << 20, 7);
  const auto t0 = Clock::now();
  int pushed = 0;
  for (int i = 0; i < 200 && box.push(chunk); ++i) ++pushed;
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_LT(pushed, 200) << "a peer that never reads took 200 MB";
  EXPECT_LT(s, 0.5) << pushed << " pushes took " << s << " s: the pusher waited for the peer";
  EXPECT_EQ(drops, 1);
  EXPECT_NE(why.find("not reading"), std::string::npos) << why;
  EXPECT_FALSE(conn->alive());
  EXPECT_FALSE(box.push(chunk));  // dropped: nothing more is taken
  // Dropped for real: the peer sees the connection end after what was sent.
  const auto got = read_n(p.peer, std::size_t(1) << 30);
  EXPECT_LT(got.size(), std::size_t(pushed + 1) << 20);
}

TEST(Outbox, AMessageNotTakenWithinItsDeadlineDropsTheClient) {
  Pair p(4096);
  auto conn = std::make_shared<Connection>(p.server, 300, 60000, nullptr);  // 0.3 s + 0.1 s per MB
  std::atomic<int> drops{0};
  Outbox box(conn, 64 << 20, [&](const std::string&) { ++drops; });
  const auto t0 = Clock::now();
  ASSERT_TRUE(box.push(std::vector<std::uint8_t>(8 << 20, 1)));  // more than the buffers hold
  box.flush(5000);
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_EQ(drops, 1);
  EXPECT_FALSE(conn->alive());
  EXPECT_GT(s, 0.3);
  EXPECT_LT(s, 3.0) << "the deadline is for the whole message";
}

TEST(ServiceSocket, QuietTimeCountsFromTheConnectionThenFromTheLastByteAndNeverClosesIt) {
  Pair p;
  Connection c(p.server, 2000, 60000, nullptr);
  EXPECT_LT(c.quiet_ms(), 200);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_GE(c.quiet_ms(), 300) << "no byte yet: quiet since the connection";
  EXPECT_LT(c.quiet_ms(), 1500);

  // A peer only quiet is never closed by reading: read() waits on (here until the byte comes).
  std::thread writer([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    ::send(p.peer, "x", 1, MSG_NOSIGNAL);
  });
  std::uint8_t b[1];
  EXPECT_EQ(c.read(b, 1, true), 1u);
  writer.join();
  EXPECT_LT(c.quiet_ms(), 200) << "a byte came: quiet from it";
  EXPECT_TRUE(c.alive());
  std::this_thread::sleep_for(std::chrono::milliseconds(250));
  EXPECT_GE(c.quiet_ms(), 250);
}

}  // namespace
}  // namespace isotouch::service
