// The OpenIGTLink device (`--haptic igtl:`, service/igtl_device.h): its spec, its connection
// errors, and its reader and writer threads against a PLUS-like peer in this process, with
// this test's thread as the servo (read, write the force, every millisecond). The truth is
// what the peer RECEIVED. Built without Vulkan, so it also runs under ThreadSanitizer.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <sstream>
#include <string>
#include <stdexcept>
#include <thread>
#include <vector>

#include "isotouch/service/igtl_device.h"
#include "isotouch/service/igtl_message.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/plus_peer.h"
#include "isotouch/servo/exit_zero.h"

namespace isotouch::service {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

TEST(ServiceIgtlDevice, SpecAndConnectionErrorsNameThePart) {
  const IgtlDeviceOptions o = parse_igtl_spec("plus.local:18944:StylusToReference");
  EXPECT_EQ(o.host, "plus.local");
  EXPECT_EQ(o.port, 18944);
  EXPECT_EQ(o.stream, "StylusToReference");
  EXPECT_EQ(parse_igtl_spec("127.0.0.1:7").stream, "StylusToTracker");
  const std::pair<const char*, const char*> bad[] = {{"127.0.0.1", "port ''"},
                                                     {"127.0.0.1:0", "port '0'"},
                                                     {"127.0.0.1:80x", "port '80x'"},
                                                     {":18944", "no host"},
                                                     {"h:1:", "stream ''"},
                                                     {"h:1:ABCDEFGHIJKLMNOPQRSTU", "stream 'ABCDEFGHIJKLMNOPQRSTU'"}};
  for (const auto& [spec, why] : bad) {
    try {
      parse_igtl_spec(spec);
      ADD_FAILURE() << spec << " was taken";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  }
  // Nothing listens there: refused at once, naming the address.
  int port = 0;
  {
    Listener l("127.0.0.1", 0);
    port = l.port();
  }  // closed: nobody listens there now
  try {
    IgtlDeviceOptions none;
    none.host = "127.0.0.1";
    none.port = port;
    none.measure_s = 0.1;
    IgtlDevice d(none);
    ADD_FAILURE() << "connected to a port nobody listens on";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(port)), std::string::npos) << e.what();
  }
}

/// A PLUS-like peer (service/plus_peer.h) the device connects to: streams "StylusToTracker"
/// (10, 20, 30 mm) at `rate_hz` for `stream_s`, then stays silent, or closes the connection at
/// `close_s` (> 0); keeps every "Force" it receives with its time.
PlusPeerOptions peer_options(double rate_hz, double stream_s, double close_s = 0) {
  PlusPeerOptions o;
  o.rate_hz = rate_hz;
  o.stream_s = stream_s;
  o.close_s = close_s;
  o.pose_mm = {10, 20, 30};
  return o;
}
double since_stream_s(const PlusPeer& p, std::int64_t t_ns) { return double(t_ns - p.started_ns()) * 1e-9; }
/// A Force the peer got, timed since its stream began [s].
struct Got {
  double t_s;
  core::Vec3 f;
};
std::vector<Got> forces_s(const PlusPeer& p) {
  std::vector<Got> g;
  for (const PeerForce& f : p.forces()) g.push_back({since_stream_s(p, f.t_ns), f.f});
  return g;
}

// The servo's force answers the stream's poses; when the stream stops (the servo still
// writing, as a servo that has not yet judged it stale), the peer gets an exact zero within
// the stale timeout (3 stream periods) and nothing else after; closing sends zero. Over this
// real socket the zero's time carries the machine's scheduling (0.1 s allowed); the rule's own
// timing, at the first poll past 3 periods, is exact in test_igtl_reply_rule.cpp.
TEST(ServiceIgtlDevice, ForcesAnswerPosesAndAStaleStreamGetsZero) {
  PlusPeer peer(peer_options(500, 0.8));
  IgtlDeviceOptions o;
  o.host = "127.0.0.1";
  o.port = peer.port();
  o.measure_s = 0.3;
  const core::Vec3 f{-1.0, 0.5, 0.25};  // exact in the TRANSFORM's float32
  std::size_t until_close = 0;  // forces the peer had before the device closed
  {
    IgtlDevice d(o);
    // The rate the peer really sent at (a loaded machine slows its 500 Hz), from its own clock.
    const std::vector<std::int64_t> sent = peer.poses_ns();
    ASSERT_GE(sent.size(), 10u) << "the peer sent almost nothing while the device measured";
    const double peer_hz = double(sent.size() - 1) / (double(sent.back() - sent.front()) * 1e-9);
    EXPECT_NEAR(d.measured_rate_hz(), peer_hz, 0.25 * peer_hz) << "the peer sent at " << peer_hz << " Hz";
    EXPECT_LT(d.measured_rate_hz(), 520.0) << "the peer never sends faster than 500 Hz";
    EXPECT_NEAR(d.caps().stale_timeout_s, 3.0 / d.measured_rate_hz(), 1e-12);
    // A stall time far above this thread's hiccups under load: the zeros this test judges are
    // the stale stream's, not a stall's (AStalledServoGetsTheZeroAtOnceNotWithTheNextPose).
    d.enable_force(true, 0.2);
    const Clock::time_point t0 = Clock::now();
    for (long k = 0; since(t0) < 0.9; ++k) {  // the stream stops 0.5 s in (0.3 s went to measuring)
      const servo::DeviceReading r = d.read();
      EXPECT_NE(r.status, servo::DeviceStatus::kDisconnected) << "the peer stays connected";
      EXPECT_NEAR(r.position_m.x, 0.010, 1e-9);  // mm -> m, the stream's frame
      d.write_force_n(f);
      std::this_thread::sleep_until(t0 + std::chrono::microseconds(1000 * (k + 1)));
    }
    until_close = peer.forces().size();
  }  // the destructor sends zero
  for (int i = 0; i < 200 && peer.forces().size() <= until_close; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const std::vector<Got> got = forces_s(peer);
  ASSERT_FALSE(got.empty()) << "the peer got no Force";
  const double stopped = peer.stopped_ns() > 0 ? since_stream_s(peer, peer.stopped_ns()) : 1e9;
  std::size_t exact = 0;
  for (const Got& g : got) {
    if (g.t_s >= stopped) break;
    const bool is_f = g.f.x == f.x && g.f.y == f.y && g.f.z == f.z;
    exact += is_f;
    // Zero before the servo's first write, or after a stall of this thread (> 0.2 s).
    EXPECT_TRUE(is_f || core::norm(g.f) == 0.0) << "a force neither the servo's nor zero at " << g.t_s << " s";
  }
  std::size_t streamed = 0;  // poses sent while the servo wrote (after the measurement)
  for (std::int64_t t : peer.poses_ns()) streamed += since_stream_s(peer, t) >= got.front().t_s;
  EXPECT_GT(exact, streamed / 4) << "the servo's force answering the stream's " << streamed << " poses";
  EXPECT_GT(exact, 10u) << "the servo's force answering the stream's poses";
  // After the stream stopped: late answers to its last poses (the servo's force, possibly
  // after a zero of this thread's own stall), then a zero and nothing but zeros.
  const Got* last_force = nullptr;
  int late_answers = 0;
  for (const Got& g : got) {
    if (g.t_s < stopped || core::norm(g.f) == 0.0) continue;
    ++late_answers;
    last_force = &g;
    EXPECT_TRUE(g.f.x == f.x && g.f.y == f.y && g.f.z == f.z) << "a late answer not the servo's force, at " << g.t_s << " s";
  }
  const Got* first_zero = nullptr;
  for (const Got& g : got)
    if (g.t_s >= stopped && (!last_force || &g > last_force)) {
      first_zero = &g;  // every force after the last late answer is a zero (checked above)
      break;
    }
  ASSERT_NE(first_zero, nullptr) << "no zero after the stream stopped: the peer holds the last force";
  EXPECT_LE(late_answers, 3) << "answers long after the stream stopped";
  EXPECT_LT(first_zero->t_s - stopped, 3.0 / 500 + 0.1) << "the stale zero came late";
  EXPECT_GT(got.size(), until_close) << "no zero at close";
}

// The peer closes the connection while the servo reads: the reading says disconnected (the
// servo's zero force and exit 5 follow from it) within a few milliseconds, not before.
TEST(ServiceIgtlDevice, APeerThatClosesReadsAsDisconnected) {
  PlusPeer peer(peer_options(500, 0.5, 0.6));
  IgtlDeviceOptions o;
  o.host = "127.0.0.1";
  o.port = peer.port();
  o.measure_s = 0.3;
  IgtlDevice d(o);
  d.enable_force(true, 0.0025);
  double first_disconnected = 0;
  const Clock::time_point t0 = Clock::now();
  for (long k = 0; since(t0) < 0.6 && first_disconnected == 0; ++k) {
    if (d.read().status == servo::DeviceStatus::kDisconnected) first_disconnected = double(PlusPeer::now_ns()) * 1e-9;
    d.write_force_n({0.5, 0, 0});
    std::this_thread::sleep_until(t0 + std::chrono::microseconds(1000 * (k + 1)));
  }
  const double closed = double(peer.closed_ns()) * 1e-9;
  ASSERT_GT(closed, 0) << "the peer did not close";
  ASSERT_GT(first_disconnected, 0) << "the device never read as disconnected";
  EXPECT_GE(first_disconnected, closed) << "disconnected before the peer closed";
  EXPECT_LT(first_disconnected - closed, 0.1) << "the close was seen late";
}


// The servo stops writing between two poses of a slow stream (10 Hz: 100 ms apart): the
// peer gets a zero within the stall time and the writer's poll (a 20 ms stall time here, so
// that this test thread, the servo, is not judged stalled while it writes on a loaded
// machine), not with the next pose ~95 ms later (judged on the peer's clock: no pose went out
// between the last force and the zero); the stall is counted.
TEST(ServiceIgtlDevice, AStalledServoGetsTheZeroAtOnceNotWithTheNextPose) {
  PlusPeer peer(peer_options(10, 6.0));
  IgtlDeviceOptions o;
  o.host = "127.0.0.1";
  o.port = peer.port();
  o.measure_s = 1.5;  // 15 poses expected, 10 needed: a loaded machine may delay the peer's (9 of 11 in 1.1 s once, load 13)
  IgtlDevice d(o);
  d.enable_force(true, 0.020);
  const core::Vec3 f{0.5, 0, 0};
  const Clock::time_point t0 = Clock::now();
  std::uint64_t seq = d.read().sequence;
  int poses_seen = 0;
  // Write every ms until the third new pose, then 5 ms more, then stop.
  for (long k = 0; since(t0) < 2.0; ++k) {
    const std::uint64_t now_seq = d.read().sequence;
    if (now_seq != seq) seq = now_seq, ++poses_seen;
    d.write_force_n(f);
    std::this_thread::sleep_until(t0 + std::chrono::microseconds(1000 * (k + 1)));
    if (poses_seen >= 3) {
      const Clock::time_point pose_at = Clock::now();
      while (since(pose_at) < 0.005) {
        d.write_force_n(f);
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      break;
    }
  }
  const std::size_t before = peer.forces().size();
  const std::uint64_t stalls_before = d.stalls();
  for (int i = 0; i < 200 && d.stalls() == stalls_before; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const std::vector<Got> got = forces_s(peer);
  std::vector<double> poses;
  for (std::int64_t t : peer.poses_ns()) poses.push_back(since_stream_s(peer, t));
  ASSERT_GE(poses_seen, 3) << "the stream did not flow";
  EXPECT_EQ(d.stalls(), stalls_before + 1);
  ASSERT_GT(before, 0u) << "no force before the stall";
  ASSERT_GT(got.size(), before) << "no zero after the servo's last write";
  for (std::size_t i = before; i < got.size(); ++i)
    EXPECT_EQ(core::norm(got[i].f), 0.0) << "a force after the stall at " << got[i].t_s << " s";
  const double last_force = got[before - 1].t_s, zero = got[before].t_s;
  long poses_between = 0;
  for (double t : poses) poses_between += t > last_force && t < zero;
  EXPECT_EQ(poses_between, 0) << "the zero came " << (zero - last_force) * 1e3 << " ms after the last force, with a pose";
}

/// A child process that opens the device on `port`, has a thread write 0.5 N every ms as the
/// servo would for 300 ms, then ends as `how` says: "crash" (SIGSEGV: the fatal-signal
/// handler), "exit" (send_exit_zeros then _Exit, as a servo stuck in its renderer ends).
void child_then_end(int port, const char* how) {
  struct rlimit none {0, 0};
  setrlimit(RLIMIT_CORE, &none);  // no core file from the crash
  IgtlDeviceOptions o;
  o.host = "127.0.0.1";
  o.port = port;
  o.measure_s = 0.3;
  IgtlDevice d(o);
  d.enable_force(true, 0.0025);
  std::atomic<bool> go{true};
  std::thread servo([&] {
    while (go.load()) {
      d.read();
      d.write_force_n({0.5, 0, 0});
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  });
  // 0.3 s, and on a loaded machine on until the force has flowed (40 Forces sent: the parent
  // asks for more than 20 of 0.5 N), 5 s at most.
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(300) ||
         (d.forces_sent() < 40 && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(5)))
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (std::string(how) == "crash") std::raise(SIGSEGV);  // the servo thread still writing
  servo::send_exit_zeros(5000);
  std::_Exit(3);
}

// However the process ends - a crash, or the _Exit of a servo stuck in its renderer - the
// peer's last Force is an exact zero, after forces of 0.5 N (PLUS applies the latest Force
// it got with no age check).
TEST(ServiceIgtlDevice, ACrashOrAStuckServosExitLeavesThePeerAZero) {
#if defined(__SANITIZE_THREAD__)
  // ThreadSanitizer ends a child forked from a process with threads (die_after_fork); the
  // release build runs this test.
  GTEST_SKIP() << "fork() from a multi-threaded process under ThreadSanitizer";
#endif
  for (const char* how : {"crash", "exit"}) {
    PlusPeer peer(peer_options(500, 3.0));
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) child_then_end(peer.port(), how);  // never returns
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    if (std::string(how) == "crash") EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGSEGV) << how;
    else EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 3) << how;
    // The peer has read all that was sent once its reader saw the connection end.
    for (int i = 0; i < 5000 && !peer.client_gone(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    EXPECT_TRUE(peer.client_gone()) << how << ": the dead child's connection did not end";
    const std::vector<Got> got = forces_s(peer);
    long forced = 0;
    for (const Got& g : got) forced += g.f.x == 0.5;
    EXPECT_GT(forced, 20) << how << ": the servo's force did not flow";
    ASSERT_FALSE(got.empty()) << how;
    EXPECT_EQ(core::norm(got.back().f), 0.0) << how << ": the peer's last force is " << got.back().f.x << " N";
  }
}


// The stiffness check of `--haptic igtl:` (issue 67) at the boundary: open_igtl_device against a
// PLUS-like peer streaming at 100 Hz, the scene's device that of tests/igtl_hand_peer.cpp and
// the link sweep (80 g, b 1 N s/m, a 50 N/m hand without damping; B 0), K 800 N/m. Colgate and
// Schenkel allow 2 b / T = 200 N/m at 100 Hz, so K 800 was refused before the link's
// simulated bound came in. The bounds the refusal names are checked against sim::link_k_max
// at the rate the description says was measured (its numbers equal `isotouch stability`'s
// table: test_linked_contact LinkKMax.*); the verdicts against that table's 100 Hz, 0 ms row
// (176 N/m without, 6043 N/m with the controller at the device end).
IgtlLoop hand_peer_loop(double k, bool peer_pc) {
  IgtlLoop l;
  l.servo_rate_hz = 1000;
  l.device = sim::LinkedContact{}.device;  // igtl_hand_peer's device, the sweep's press
  l.handle_damping_n_s_per_m = l.device.damping_n_s_per_m + l.device.hand_damping_n_s_per_m;
  l.servo_damping_n_s_per_m = 0;
  l.stiffness_n_per_m = k;
  l.peer_passivity_control = peer_pc;
  return l;
}

/// The rate the description says was measured [Hz].
double measured_in(const std::string& text) {
  const std::size_t at = text.find(" Hz measured");
  EXPECT_NE(at, std::string::npos) << text;
  if (at == std::string::npos) return 0;
  const std::size_t from = text.rfind(" at ", at);
  return std::stod(text.substr(from + 4, at - from - 4));
}

std::string num4(double v) {
  std::ostringstream o;
  o.precision(4);
  o << v;
  return o.str();
}

TEST(ServiceIgtlDevice, TheStiffnessBoundIsTheLinksWithThePeersControllerOnlyWhenItRunsOne) {
  struct Case {
    double k;
    bool peer_pc, opens;
  };
  for (const Case c : {Case{800, false, false}, Case{800, true, true}, Case{8000, true, false}}) {
    PlusPeer peer(peer_options(100, 2.0));
    std::string description, refusal;
    try {
      auto d = open_igtl_device("127.0.0.1:" + std::to_string(peer.port()), hand_peer_loop(c.k, c.peer_pc), description);
    } catch (const std::runtime_error& e) {
      refusal = e.what();
    }
    const std::string& text = refusal.empty() ? description : refusal;
    SCOPED_TRACE("K " + num4(c.k) + ", the peer's controller " + (c.peer_pc ? "on" : "off") + ": " + text);
    EXPECT_EQ(refusal.empty(), c.opens);
    const double rate = measured_in(text);
    ASSERT_GT(rate, 20) << "the 100 Hz peer was measured at " << rate << " Hz";
    // Both bounds, each the simulation's at the measured rate with no round trip beyond the hold.
    const sim::LinkBound b = sim::link_k_max([] {
      sim::LinkedContact p;
      p.device.force_max_n = 1e3;
      return p;
    }(), rate, 0);
    EXPECT_NE(text.find("K_max " + num4(b.k_max_n_per_m) + " N/m without the passivity controller, " +
                        num4(b.k_max_with_pc_n_per_m) + " N/m with it"),
              std::string::npos);
    EXPECT_NE(text.find("round trip 0 ms beyond the hold"), std::string::npos);
    EXPECT_EQ(text.find("warning"), std::string::npos);
    if (!c.opens) {
      EXPECT_NE(refusal.find("servo.stiffness_n_per_m " + num4(c.k) + " is above the bound"), std::string::npos);
      EXPECT_NE(refusal.find("--allow-unstable-stiffness"), std::string::npos);
      // Only a K the controller makes passive is told to run it.
      EXPECT_EQ(refusal.find("device.link_passivity_control: true") == std::string::npos, c.peer_pc);
    }
  }
}

}  // namespace
}  // namespace isotouch::service
