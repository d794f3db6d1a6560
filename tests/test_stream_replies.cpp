// serve's TRANSFORM stream replies (`serve --reply-force`, service/stream_replies.h) judged on
// what a PLUS-like client RECEIVED (service/plus_peer.h): the servo's force answers each pose;
// a stale stream, a client that stops being the stream's, the end of the loop and a crash of
// the process each leave the client an exact zero as its last Force. This test's thread is the
// servo (read, write the force, every millisecond). No Vulkan: also under ThreadSanitizer.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <functional>
#include <thread>
#include <vector>

#include "isotouch/service/plus_peer.h"
#include "isotouch/service/stream_host.h"
#include "isotouch/service/stream_replies.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/exit_zero.h"
#include "sched_canary.h"

namespace isotouch {
namespace {

using service::PeerForce;
using service::PlusPeer;
using service::PlusPeerOptions;

/// SCHED_FIFO for the servo, the reply thread and the client where allowed (root), as serve
/// and PLUS run them: the tests time in milliseconds, and a loaded machine's scheduler is not
/// the code under test.
const bool kFifo = geteuid() == 0;

PlusPeerOptions client_of(int port, double stream_s = 0) {
  PlusPeerOptions o;
  o.connect_host = "127.0.0.1";
  o.connect_port = port;
  o.rate_hz = 500;
  o.stream_s = stream_s;
  o.fifo_priority = kFifo ? 60 : 0;
  return o;
}

/// The servo: writes `f` every ms while `more()`, with the force enabled at a stall time of
/// 20 ms, from a thread at the servo's priority where allowed.
void serve_forces(service::TransformDevice& d, const core::Vec3& f, const std::function<bool()>& more) {
  d.enable_force(true, 0.020);
  std::thread servo([&] {
    if (kFifo) servo::make_thread_realtime("test servo", true, 80, false, -1);
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; more(); ++k) {
      d.read();
      d.write_force_n(f);
      std::this_thread::sleep_until(t0 + std::chrono::microseconds(1000 * (k + 1)));
    }
  });
  servo.join();
}

bool is(const core::Vec3& a, const core::Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

/// Waits up to 2 s for `done`.
void wait_for(const std::function<bool()>& done) {
  for (int i = 0; i < 2000 && !done(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

// Each pose is answered with the servo's force (RAS: the grid's x and y negated with the
// default frame's identity direction) and the pose's stamp; when the loop stops, its last
// act leaves the client a zero.
TEST(StreamReplies, PosesAreAnsweredWithTheServosForceAndTheLastActIsAZero) {
  service::StreamHost host({kFifo, 0.1});
  PlusPeer peer(client_of(host.port()));
  const core::Vec3 f{0.25, -0.5, 1.0}, ras{-0.25, 0.5, 1.0};  // exact in float32
  const std::int64_t t0 = PlusPeer::now_ns();
  serve_forces(host.device(), f, [&] { return PlusPeer::now_ns() - t0 < 400'000'000; });
  host.stop();
  wait_for([&] { const auto g = peer.forces(); return !g.empty() && core::norm(g.back().f) == 0.0; });
  peer.finish();
  const std::vector<PeerForce> got = peer.forces();
  long answers = 0, stamped = 0;
  for (const PeerForce& g : got) {
    answers += is(g.f, ras);
    stamped += g.stamp != 0;
    EXPECT_TRUE(is(g.f, ras) || core::norm(g.f) == 0.0) << "neither the servo's force nor zero";
  }
  // 500 poses a second for 0.4 s; the host's reader (serve's client threads are not real-time)
  // keeps only the newest pose when a loaded machine delays it.
  EXPECT_GT(answers, 5) << "the servo's force answers the poses";
  EXPECT_EQ(stamped, long(got.size())) << "every reply carries a stamp";
  ASSERT_FALSE(got.empty());
  EXPECT_EQ(core::norm(got.back().f), 0.0) << "the client was left holding " << got.back().f.z << " N";
  EXPECT_EQ(host.replies().replies(), long(got.size()) - 1) << "replies counted, the last zero apart";
}

// The servo stops writing between two poses of a slow stream (10 Hz: 100 ms apart): the
// client gets a zero within the stall time (20 ms here) and the reply thread's poll, not with
// the next pose; judged on the client's clock (no pose went out between the last force and
// the zero).
TEST(StreamReplies, AStalledServoGetsTheZeroAtOnceNotWithTheNextPose) {
  service::StreamHost host({kFifo, 1.0});
  PlusPeerOptions o = client_of(host.port());
  o.rate_hz = 10;
  PlusPeer peer(o);
  service::TransformDevice& d = host.device();
  std::uint64_t seq = 0;
  int poses_seen = 0;
  std::int64_t stop_at = 0;  // 5 ms after the third pose the servo saw
  serve_forces(d, {0, 0, 0.5}, [&] {
    const std::uint64_t now_seq = d.read().sequence;
    if (now_seq != seq) seq = now_seq, ++poses_seen;
    if (poses_seen == 3 && stop_at == 0) stop_at = PlusPeer::now_ns() + 5'000'000;
    return PlusPeer::now_ns() - stop_at < 0 || stop_at == 0;
  });
  const std::uint64_t stalls = d.stalls();
  wait_for([&] { return d.stalls() > stalls; });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const std::vector<PeerForce> got = peer.forces();
  const std::vector<std::int64_t> poses = peer.poses_ns();
  ASSERT_GE(poses_seen, 3) << "the stream did not flow";
  std::size_t last_force = got.size();
  for (std::size_t i = 0; i < got.size(); ++i)
    if (got[i].f.z == 0.5) last_force = i;
  ASSERT_LT(last_force + 1, got.size()) << "no zero after the servo's last write";
  const PeerForce& zero = got[last_force + 1];
  EXPECT_EQ(core::norm(zero.f), 0.0);
  long poses_between = 0;
  for (std::int64_t t : poses) poses_between += t > got[last_force].t_ns && t < zero.t_ns;
  EXPECT_EQ(poses_between, 0) << "the zero came " << double(zero.t_ns - got[last_force].t_ns) * 1e-6
                              << " ms after the last force, with a pose";
}

// The next pose arrives right after the servo's answer to the last, before the reply thread's
// poll (this test's servo pushes it itself): each pose the servo answered still gets its reply,
// its own force with its own stamp, instead of being passed over for the newer pose (which
// the servo answers a tick later, by which time the next has come). Before, the replies
// waited for the servo to answer the newest pose and almost none went out.
TEST(StreamReplies, APoseTheServoAnsweredIsAnsweredThoughANewerOneCame) {
  service::StreamHost host({kFifo, 1.0});
  PlusPeer peer(client_of(host.port(), 0.02));  // a few poses: the client becomes the replies' target
  wait_for([&] { return peer.stopped_ns() > 0; });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // its poses read and answered
  service::TransformDevice& d = host.device();
  constexpr std::uint64_t kStamp0 = std::uint64_t(1) << 40;
  constexpr long kPoses = 200, kRamp = 80;  // the first 80 ms: the force's ramp-in (stall rule), not judged
  const double mm[3] = {0, 0, 0};
  d.enable_force(true, 0.020);
  d.push_mm(mm, kStamp0 - kRamp);
  std::thread servo([&] {
    if (kFifo) servo::make_thread_realtime("test servo", true, 80, false, -1);
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = -kRamp; k < kPoses; ++k) {
      const std::uint64_t stamp = kStamp0 + std::uint64_t(k);
      d.read();
      d.write_force_n({0, 0, double(k + 1) / 1024});  // pose k's force: exact in float32
      d.push_mm(mm, stamp + 1);                        // the next pose, at once
      std::this_thread::sleep_until(t0 + std::chrono::microseconds(1000 * (k + kRamp + 1)));
    }
  });
  servo.join();
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  host.stop();
  peer.finish();
  long answered = 0, other = 0;
  std::uint64_t last = 0;
  for (const PeerForce& g : peer.forces()) {
    if (g.stamp < kStamp0 || g.stamp >= kStamp0 + kPoses) continue;
    const double own = double(g.stamp - kStamp0 + 1) / 1024;
    // Its own force, or (the stall rule: a pose the servo has not answered within 2 ms, as
    // this test's servo on a loaded machine) an older pose's: never a newer one's.
    if (g.f.z == own) ++answered;
    else ++other;
    EXPECT_LE(g.f.z, own) << "the reply to the pose stamped " << g.stamp - kStamp0 << " carries a newer pose's force";
    EXPECT_GT(g.stamp, last) << "a pose answered twice or out of order";
    last = g.stamp;
  }
  // The reply thread (SCHED_FIFO below this servo where allowed) polls every 20-100 us; a
  // poll later than a whole servo period passes one pose over.
  std::printf("%ld of %ld poses answered with their own force, %ld with an older one's (stall rule: %ld replies), %ld passed over\n",
              answered, kPoses, other, host.replies().stall_replies(), host.replies().passed_over());
  EXPECT_LE(other, host.replies().stall_replies()) << "replies with another pose's force the stall rule did not send";
  EXPECT_GE(answered, kPoses * 3 / 4) << "of " << kPoses << " poses the servo answered, " << answered
                                      << " were answered to the client; passed over: " << host.replies().passed_over();
}

// The client stops sending poses while the servo still writes (it has not judged the stream
// stale yet): once the host has had no pose for the reply thread's stale time, the client gets
// one zero and nothing but zeros after it (timed from the last pose the host received: a
// loaded host reads queued poses late, and answers them).
TEST(StreamReplies, AStaleStreamLeavesTheClientAZero) {
  service::StreamHost host({kFifo, 0.006});
  PlusPeer peer(client_of(host.port(), 0.3));
  isotouch::test::SchedCanary canary;  // how long the machine was gone: widens the zero's bound by that alone
  const std::int64_t t0 = PlusPeer::now_ns();
  serve_forces(host.device(), {0, 0, 0.5}, [&] { return PlusPeer::now_ns() - t0 < 600'000'000; });
  canary.stop();
  const std::vector<PeerForce> got = peer.forces();
  ASSERT_GT(peer.stopped_ns(), 0) << "the stream did not stop";
  const std::int64_t stale_at = host.device().newest_pose().received_ns + 6'000'000;
  std::size_t first_zero = got.size();
  long forced = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    forced += got[i].f.z == 0.5;
    if (got[i].t_ns > stale_at && core::norm(got[i].f) == 0.0 && first_zero == got.size()) first_zero = i;
  }
  EXPECT_GT(forced, 5) << "the servo's force never reached the client";
  ASSERT_LT(first_zero, got.size()) << "no zero after the stream went stale: the client holds 0.5 N";
  for (std::size_t i = first_zero; i < got.size(); ++i) EXPECT_EQ(core::norm(got[i].f), 0.0) << "a force after the zero";
  // Within 3 servo periods of the stream going stale (the reply thread looks every 0.1 ms),
  // and the time the canaries saw the machine gone.
  const std::int64_t late_ns = got[first_zero].t_ns - stale_at;
  std::printf("the stale zero reached the client %.3f ms after the stream went stale (%s)\n", double(late_ns) * 1e-6,
              canary.describe(stale_at, got[first_zero].t_ns).c_str());
  EXPECT_LE(late_ns, 3'000'000 + canary.lost_ns(stale_at, got[first_zero].t_ns))
      << "the stale zero came late: " << canary.describe(stale_at, got[first_zero].t_ns);
  // One zero, not one a poll (a stall of this loaded test's servo sends one more, whole).
  EXPECT_LE(got.size() - first_zero, 1u + host.device().stalls()) << "zeros after the stream went stale";
}

// Client A streams and gets the force; then client B takes the stream over: A's last Force is
// a zero (it applies the last one it got), B gets the servo's force.
TEST(StreamReplies, AClientThatStopsBeingTheStreamsIsLeftAZero) {
  service::StreamHost host({kFifo, 0.1});
  PlusPeer a(client_of(host.port()));
  std::unique_ptr<PlusPeer> b;
  const std::int64_t t0 = PlusPeer::now_ns();
  serve_forces(host.device(), {0, 0, 0.5}, [&] {
    const std::int64_t t = PlusPeer::now_ns() - t0;
    if (t > 200'000'000 && !b) a.pause(true), b = std::make_unique<PlusPeer>(client_of(host.port()));
    return t < 500'000'000;
  });
  host.stop();
  const std::vector<PeerForce> got_a = a.forces(), got_b = b->forces();
  long a_forced = 0, b_forced = 0;
  for (const PeerForce& g : got_a) a_forced += g.f.z == 0.5;
  for (const PeerForce& g : got_b) b_forced += g.f.z == 0.5;
  EXPECT_GT(a_forced, 0) << "A never got the force";
  EXPECT_GT(b_forced, 0) << "B never got the force";
  ASSERT_FALSE(got_a.empty());
  EXPECT_EQ(core::norm(got_a.back().f), 0.0) << "A was left holding a force";
  // A's zero came when B took over, not at the end (it is A's last message well before).
  EXPECT_LT(got_a.back().t_ns, got_b.back().t_ns - 100'000'000);
}

/// A child process that serves the stream on a port it writes to `fd`, writes 0.5 N every ms
/// as the servo would for 400 ms, then crashes (SIGSEGV: the fatal-signal handler), or ends
/// as a servo stuck in its renderer ends ("exit": send_exit_zeros, then _Exit).
[[noreturn]] void child_then_end(int fd, const char* how) {
  struct rlimit none {0, 0};
  setrlimit(RLIMIT_CORE, &none);  // no core file from the crash
  service::StreamHost host({kFifo, 0.1});
  const int port = host.port();
  if (write(fd, &port, sizeof port) != sizeof port) std::_Exit(2);
  const std::int64_t t0 = PlusPeer::now_ns();
  serve_forces(host.device(), {0, 0, 0.5}, [&] { return PlusPeer::now_ns() - t0 < 400'000'000; });
  if (std::string(how) == "crash") std::raise(SIGSEGV);  // the reply thread still answering
  servo::send_exit_zeros(5000);
  std::_Exit(3);
}

TEST(StreamReplies, ACrashOrAStuckServosExitLeavesTheClientAZero) {
#if defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "fork() from a multi-threaded process under ThreadSanitizer (die_after_fork)";
#endif
  for (const char* how : {"crash", "exit"}) {
    int p[2];
    ASSERT_EQ(pipe(p), 0);
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) child_then_end(p[1], how);
    close(p[1]);
    int port = 0;
    ASSERT_EQ(read(p[0], &port, sizeof port), ssize_t(sizeof port)) << how;
    close(p[0]);
    PlusPeer peer(client_of(port));
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    if (std::string(how) == "crash") EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGSEGV) << how;
    else EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 3) << how;
    wait_for([&] { return peer.client_gone(); });
    EXPECT_TRUE(peer.client_gone()) << how << ": the dead server's connection did not end";
    peer.finish();
    const std::vector<PeerForce> got = peer.forces();
    long forced = 0;
    for (const PeerForce& g : got) forced += g.f.z == 0.5;
    EXPECT_GT(forced, 5) << how << ": the servo's force did not flow";
    ASSERT_FALSE(got.empty()) << how;
    EXPECT_EQ(core::norm(got.back().f), 0.0) << how << ": the client's last force is " << got.back().f.z << " N";
  }
}

}  // namespace
}  // namespace isotouch
