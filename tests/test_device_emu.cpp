// End to end against the device emulator in real time at 1 kHz: the servo thread drives a
// ReportDevice over the socket link to a DeviceEmulator (protocol v1) whose simulated hand
// presses into a penalty wall. Disconnect (the emulator gone) -> zero force within one tick;
// freeze -> zero force after the stale timeout; garbage -> counted and named, no crash;
// reconnect -> the force ramps in again; sequence faults counted; a servo that stalls ->
// zero force with enable cleared within 3 periods, then a ramp; a frozen writer -> the
// device's watchdog; a renderer that never returns -> force off and stop() gives up.
// The forces are asserted as the emulator received them on the wire (its output log).
#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <thread>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/device_emulator.h"
#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/socket_link.h"
#include "isotouch/tests/sched_canary.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

namespace {
/// A wall at device z = 0 (inside below): F = 500 N/m x depth along +z.
class Wall final : public Renderer {
 public:
  const char* name() const override { return "wall"; }
  void reset() override {}
  HriTick tick(const FieldView&, const Vec3& hip, double) override {
    HriTick t;
    if (hip.z < 0) t.force_n = {0, 0, -500.0 * hip.z};
    return t;
  }
};

/// A socket link whose writes block while `frozen` is set: the device's writer thread
/// stops there, as a starved or stopped thread would.
class FreezableLink final : public ReportLink {
 public:
  FreezableLink(const std::string& path, std::atomic<bool>& frozen) : link_(path), frozen_(frozen) {}
  std::string name() const override { return link_.name(); }
  std::string open() override { return link_.open(); }
  void close() override { link_.close(); }
  int read(std::span<std::uint8_t> buf, int timeout_ms) override { return link_.read(buf, timeout_ms); }
  bool write(std::span<const std::uint8_t> report) override {
    while (frozen_.load()) std::this_thread::sleep_for(std::chrono::microseconds(200));
    return link_.write(report);
  }
  int get_feature(std::uint8_t id, std::span<std::uint8_t> buf) override { return link_.get_feature(id, buf); }

 private:
  SocketLink link_;
  std::atomic<bool>& frozen_;
};

std::int64_t mono_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

/// The wall, except that one tick in contact after `after_ticks` ticks takes `stall_ms`
/// (a slow renderer), or never returns until `release` (stall_ms < 0). Records when.
class StallingWall final : public Renderer {
 public:
  const char* name() const override { return "stalling wall"; }
  void reset() override {}
  HriTick tick(const FieldView& f, const Vec3& hip, double dt) override {
    if (++ticks_ > after_ticks && hip.z < -0.0005 && start_ns.load() == 0) {
      start_ns.store(mono_ns());
      if (stall_ms >= 0) std::this_thread::sleep_for(std::chrono::milliseconds(stall_ms));
      while (stall_ms < 0 && !release.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      end_ns.store(mono_ns());
    }
    return wall_.tick(f, hip, dt);
  }
  long after_ticks = 150;
  int stall_ms = 300;
  std::atomic<bool> release{false};
  std::atomic<std::int64_t> start_ns{0}, end_ns{0};

 private:
  Wall wall_;
  long ticks_ = 0;
};

struct TickLog final : TickObserver {
  static constexpr std::size_t kMax = 4096;
  std::array<std::int64_t, kMax> t_ns{};
  std::array<DeviceStatus, kMax> status{};
  std::array<double, kMax> force{};
  std::atomic<std::size_t> n{0};
  void on_tick(const TickRecord& r) noexcept override {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i >= kMax) return;
    t_ns[i] = r.t_ns, status[i] = r.device_status, force[i] = norm(r.force_sent_n);
    n.store(i + 1, std::memory_order_release);
  }
};

/// Emulator thread + device + servo thread for `seconds` of emulator time.
struct Rig {
  EmuConfig cfg;
  std::unique_ptr<DeviceEmulator> emu;
  std::unique_ptr<ReportDevice> dev;
  TripleBuffer<SampleField> published;
  Wall wall;
  Renderer* renderer = &wall;
  std::atomic<bool> freeze_writes{false};
  std::function<void()> while_running;  // on the test thread while the servo runs
  /// SCHED_FIFO for the emulator, the device's threads and the servo (where allowed): the
  /// tests time in servo periods, and a servo more than 2 periods late restarts its ramp
  /// (a loaded machine's scheduler is not the code under test).
  bool fifo = true;
  TickLog log;
  EmuStats stats;
  std::vector<ReceivedOutput> wire;     // what the emulator received, with times
  DeviceCounters servo_counters;
  LinkCounters link;
  std::string last_error, last_refusal, stop_error;
  hid::polhem::Config host_config = hid::polhem::kDefaultConfig;  // the host's, for a Polhem
  double stop_s = 0;                    // how long servo.stop() took [s]
  /// How long the machine was gone, measured beside the run: a wall-clock bound on the wire
  /// widens by the canaries' lost time in the interval it bounds, and by nothing else.
  isotouch::test::SchedCanary canary;

  Rig() {
    cfg.socket_path = "/tmp/isotouch-test-emu-" + std::to_string(::getpid()) + ".sock";
    cfg.rate_hz = 1000;
    cfg.hold_m = Vec3{0, 0, -0.003};  // the hand pushes 3 mm into the wall: ~0.56 N
    cfg.caps.name = "test-emu";
    cfg.caps.max_force_n = 10;
    cfg.caps.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
    cfg.caps.workspace_max_m = Vec3{0.1, 0.1, 0.1};
    cfg.caps.watchdog_s = 0.05;
    published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.016})));
  }
  void run(double seconds) {
    cfg.seconds = seconds;
    cfg.fifo_priority = fifo ? 75 : 0;
    emu = std::make_unique<DeviceEmulator>(cfg);
    emu->listen();
    std::thread emu_thread([this] { stats = emu->run(); });
    // Stopped and joined on every way out of run(): a throw before the join below (the
    // device's open() failing, the servo not starting) would destroy a joinable std::thread,
    // and std::terminate would end the whole test binary instead of failing this one test.
    struct JoinEmu {
      DeviceEmulator& emu;
      std::thread& thread;
      ~JoinEmu() {
        if (!thread.joinable()) return;  // joined below: the normal way out
        emu.stop();
        thread.join();
      }
    } join_emu{*emu, emu_thread};
    std::unique_ptr<DeviceProtocol> protocol;
    if (cfg.polhem) protocol = std::make_unique<PolhemProtocol>(host_config);
    else protocol = std::make_unique<V1Protocol>();
    dev = std::make_unique<ReportDevice>(std::make_unique<FreezableLink>(cfg.socket_path, freeze_writes),
                                         std::move(protocol), ReportDeviceOptions{.fifo_priority = fifo ? 70 : 0});
    dev->open();
    ServoThreadConfig sc;
    sc.rate_hz = 1000;
    sc.sched_fifo = fifo;
    sc.pin_cpu = sc.lock_memory = false;
    sc.observer = &log;
    {
      ServoThread servo(published, *renderer, *dev, sc);
      servo.start();
      if (while_running) while_running();
      emu_thread.join();
      const auto t0 = std::chrono::steady_clock::now();
      stop_error = servo.stop();
      stop_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      servo_counters = servo.device_counters();
    }
    wire = emu->output_log();
    link = dev->counters();
    last_error = dev->last_error();
    last_refusal = dev->last_refusal();
    dev->close();
  }
  /// Ticks that started after `t_ns` and still sent a force.
  long forced_after(std::int64_t t_ns) const {
    long k = 0;
    for (std::size_t i = 0; i < log.n.load(); ++i)
      if (log.t_ns[i] > t_ns && log.force[i] > 0) ++k;
    return k;
  }
  long forced_ticks() const {
    long k = 0;
    for (std::size_t i = 0; i < log.n.load(); ++i) k += log.force[i] > 0.3;
    return k;
  }
  /// What a failed count needs to be understood: the servo's, the link's and the
  /// emulator's counters, the ticks' statuses and the largest force sent.
  std::string summary() const {
    long by_status[5] = {};  // ok, stale, disconnected, fault, uncalibrated (DeviceStatus)
    double max_f = 0;
    for (std::size_t i = 0; i < log.n.load(); ++i) {
      ++by_status[std::min<std::size_t>(std::size_t(log.status[i]), 4)];
      max_f = std::max(max_f, log.force[i]);
    }
    std::string s = "ticks " + std::to_string(log.n.load()) + " (by status:";
    for (long c : by_status) s += " " + std::to_string(c);
    s += "), max force " + std::to_string(max_f) + " N; servo: stale " + std::to_string(servo_counters.stale) +
         ", disconnected " + std::to_string(servo_counters.disconnected) + ", fault " +
         std::to_string(servo_counters.fault) + ", uncalibrated " + std::to_string(servo_counters.uncalibrated) +
         ", refused " + std::to_string(servo_counters.refused) + ", ramps " +
         std::to_string(servo_counters.ramps) + ", late restarts " + std::to_string(servo_counters.late_restarts) +
         "; link: reports " + std::to_string(link.reports) + ", garbage " + std::to_string(link.garbage) +
         ", writes " + std::to_string(link.writes) + ", busy reads " + std::to_string(link.busy_reads) +
         ", stalls " + std::to_string(link.stalls) + ", watchdog " + std::to_string(link.watchdog_trips) +
         "; emulator: sent " + std::to_string(stats.reports_sent) + ", received " +
         std::to_string(stats.outputs_received) + ", max force " + std::to_string(stats.max_force_n) +
         " N, watchdog trips " + std::to_string(stats.watchdog_trips) + ", connections " +
         std::to_string(stats.connections);
    return s;
  }
  /// The first report on the wire at or after `t_ns` with enable cleared (wire.size(): none).
  std::size_t first_disabled_from(std::int64_t t_ns) const {
    std::size_t i = 0;
    while (i < wire.size() && (wire[i].t_ns < t_ns || wire[i].enable)) ++i;
    return i;
  }
  /// The last report before `i` that carried force with enable set.
  std::size_t last_forced_before(std::size_t i) const {
    while (i > 0 && !(wire[i - 1].enable && norm(wire[i - 1].force_n) > 0)) --i;
    return i - 1;  // wraps when there is none: callers check < i
  }
  /// Reports with force and enable set received in [from_ns, to_ns).
  long forced_on_wire(std::int64_t from_ns, std::int64_t to_ns) const {
    long k = 0;
    for (const ReceivedOutput& o : wire) k += o.t_ns >= from_ns && o.t_ns < to_ns && o.enable && norm(o.force_n) > 0;
    return k;
  }
};
}  // namespace

TEST(DeviceEmu, TheHandPressesAndTheForceFlowsBothWays) {
  Rig rig;
  rig.run(0.8);  // 150 forced ticks even after a servo that starts 400 ms late (TSan on a loaded machine: 250 ms seen)
  EXPECT_GT(rig.forced_ticks(), 150) << rig.summary();  // the wall pushed back
  // Forces reached the device: most ticks' outputs arrived (relative to the ticks the servo
  // ran, which a loaded machine or a sanitizer build makes fewer than 400 in 0.4 s).
  EXPECT_GT(rig.stats.outputs_received, 150);
  EXPECT_GT(double(rig.stats.outputs_received), 0.75 * double(rig.log.n.load()));
  EXPECT_GT(rig.stats.max_force_n, 0.3);
  EXPECT_LT(rig.stats.max_force_n, 1.5);
  EXPECT_GT(rig.forced_on_wire(0, INT64_MAX), 150);
  EXPECT_GT(rig.link.reports, 300);
  EXPECT_EQ(rig.link.garbage, 0);
  ASSERT_GT(rig.stats.latency_us.size(), 100u);
}

TEST(DeviceEmu, KilledEmulatorGivesZeroForceWithinOneTick) {
  Rig rig;
  rig.cfg.faults.disconnect_at_s = 0.3;  // the connection and the socket vanish
  rig.run(0.5);
  ASSERT_GT(rig.stats.disconnect_ns, 0);
  EXPECT_GT(rig.forced_after(rig.stats.disconnect_ns - 100'000'000), 50);  // forcing before it
  EXPECT_GT(rig.forced_on_wire(rig.stats.disconnect_ns - 100'000'000, rig.stats.disconnect_ns), 50);
  EXPECT_LE(rig.forced_after(rig.stats.disconnect_ns), 1) << "ticks after the disconnect still forced";
  EXPECT_GT(rig.servo_counters.disconnected, 100);
  EXPECT_EQ(rig.link.disconnects, 1);
  EXPECT_NE(rig.last_error.find("link down"), std::string::npos) << rig.last_error;
}

TEST(DeviceEmu, FrozenDeviceGivesZeroForceAfterTheTimeout) {
  Rig rig;
  rig.cfg.faults.freeze_at_s = 0.2;
  rig.cfg.faults.freeze_for_s = 0.1;
  rig.run(0.45);
  EXPECT_GT(rig.servo_counters.stale, 80);  // 100 ms frozen, less the 2 ms timeout
  EXPECT_LT(rig.servo_counters.stale, 120);
  for (std::size_t i = 0; i < rig.log.n.load(); ++i)
    if (rig.log.status[i] == DeviceStatus::kStale) {
      ASSERT_EQ(rig.log.force[i], 0.0) << "tick " << i;
    }
  EXPECT_GE(rig.servo_counters.ramps, 2);   // enabled, then back after the freeze
  // On the wire: the freeze is the longest run of outputs answering one input report (no
  // new ones came). From the stale timeout and a period after its start, every output is
  // a zero the servo wrote itself in its tick (enable set), not the writer's stall zero.
  std::size_t begin = 0, len = 0;
  for (std::size_t i = 0, j = 0; i < rig.wire.size(); i = j) {
    for (j = i; j < rig.wire.size() && rig.wire[j].answers == rig.wire[i].answers;) ++j;
    if (j - i > len) begin = i, len = j - i;
  }
  ASSERT_GT(len, 60u) << "outputs during the 100 ms freeze (one per servo tick)";
  // Forces came back after the freeze: from 50 ms after its end on the emulator's clock (the
  // first output answering a new report), not after the servo's start, which a loaded machine
  // delays past the emulator's (the emulator's run, and so this window, stays 100 ms long).
  ASSERT_LT(begin + len, rig.wire.size()) << "no output after the freeze";
  EXPECT_GT(rig.forced_after(rig.wire[begin + len].t_ns + 50'000'000), 50);
  long zero_enabled = 0, checked = 0;
  for (std::size_t i = begin; i < begin + len; ++i) {
    // (3 periods after the freeze's start, and the time the machine was gone in them.)
    if (rig.wire[i].t_ns - rig.wire[begin].t_ns < 3'000'000 + rig.canary.lost_ns(rig.wire[begin].t_ns, rig.wire[i].t_ns))
      continue;
    ++checked;
    ASSERT_EQ(norm(rig.wire[i].force_n), 0.0) << "output " << i - begin << " of the freeze";
    zero_enabled += rig.wire[i].enable;
  }
  EXPECT_GT(zero_enabled, 9 * checked / 10);
}

TEST(DeviceEmu, GarbageIsCountedAndNamedWithoutACrash) {
  Rig rig;
  rig.cfg.faults.garbage = 0.1;
  rig.run(0.7);
  EXPECT_GT(rig.link.garbage, 15);
  EXPECT_NE(rig.last_refusal.find("refused input report"), std::string::npos) << rig.last_refusal;
  EXPECT_GT(rig.forced_ticks(), 100) << rig.summary();  // the good reports kept the force going
}

TEST(DeviceEmu, ReconnectionRampsTheForceIn) {
  Rig rig;
  // From the device's first connection, not the emulator's start, and late enough that the
  // servo has ticked before the outage: on a loaded machine (CI's other test's FIFO threads)
  // the servo has started up to 150 ms after the connection, and a device lost before the
  // servo's first good tick gives only one ramp.
  rig.cfg.faults.disconnect_at_s = 0.3;
  rig.cfg.faults.reconnect_after_s = 0.1;
  rig.cfg.faults.from_first_connection = true;
  rig.run(0.9);
  EXPECT_EQ(rig.link.reconnects, 1);
  EXPECT_GE(rig.servo_counters.ramps, 2);
  // The first ok tick after the outage forced less than half of the steady force: the
  // force ramped in (no jolt), and it did reach the steady force later.
  std::size_t back = 0;
  for (std::size_t i = 1; i < rig.log.n.load() && back == 0; ++i)
    if (rig.log.status[i - 1] == DeviceStatus::kDisconnected && rig.log.status[i] == DeviceStatus::kOk) back = i;
  ASSERT_GT(back, 0u) << "the device never came back";
  double steady = 0;  // the force once ramped in (before the emulator's end)
  for (std::size_t i = back + 60; i < back + 200 && i < rig.log.n.load(); ++i) steady = std::max(steady, rig.log.force[i]);
  EXPECT_GT(steady, 0.3);
  EXPECT_LT(rig.log.force[back], 0.5 * steady);
  // On the wire: the first enabled output after the outage is below half the force the
  // device felt later.
  std::size_t first = 0;
  while (first < rig.wire.size() && (rig.wire[first].t_ns <= rig.stats.disconnect_ns || !rig.wire[first].enable)) ++first;
  ASSERT_LT(first, rig.wire.size()) << "nothing enabled reached the device after the outage";
  double felt = 0;
  for (std::size_t i = first; i < rig.wire.size(); ++i) felt = std::max(felt, norm(rig.wire[i].force_n));
  EXPECT_GT(felt, 0.3);
  EXPECT_LT(norm(rig.wire[first].force_n), 0.5 * felt);
}

TEST(DeviceEmu, SequenceFaultsAreCounted) {
  Rig rig;
  rig.cfg.faults.drop = 0.05;
  rig.cfg.faults.duplicate = 0.05;
  rig.cfg.faults.reorder = 0.05;
  rig.cfg.faults.delay = 0.02;
  rig.run(1.2);  // 200 forced ticks even after 0.6 s without reports (TSan: 0.6 s gave 0 forced ticks once)
  EXPECT_GT(rig.link.gaps, 5);
  EXPECT_GT(rig.link.duplicates, 5);
  EXPECT_GT(rig.link.reordered, 5);
  EXPECT_GT(rig.forced_ticks(), 200) << rig.summary();
}

TEST(DeviceEmu, ListenRefusesAnythingButASocketAtItsPathAndReplacesAStaleSocket) {
  const std::string path = "/tmp/isotouch-test-emu-precious-" + std::to_string(::getpid()) + ".txt";
  {
    std::ofstream f(path);
    f << "precious\n";
  }
  EmuConfig cfg;
  cfg.socket_path = path;
  try {
    DeviceEmulator(cfg).listen();
    FAIL() << "listened over a regular file";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path + " exists and is not a socket"), std::string::npos) << e.what();
  }
  std::ifstream in(path);
  std::string line;
  EXPECT_TRUE(std::getline(in, line) && line == "precious") << "the file was removed or changed";
  ::unlink(path.c_str());

  // A socket left behind by a killed emulator is replaced: a host connects to the new one.
  const std::string sock = "/tmp/isotouch-test-emu-stale-" + std::to_string(::getpid()) + ".sock";
  {  // bound, then closed: the socket file stays, as a killed emulator leaves it
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, sock.c_str(), sock.size() + 1);
    ::unlink(sock.c_str());
    const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET, 0);
    ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0);
    ::close(fd);
    struct stat st {};
    ASSERT_EQ(::lstat(sock.c_str(), &st), 0);
    ASSERT_TRUE(S_ISSOCK(st.st_mode));
  }
  cfg.socket_path = sock;
  DeviceEmulator emu(cfg);
  EXPECT_NO_THROW(emu.listen());
  SocketLink link(sock);
  EXPECT_EQ(link.open(), "");
}

TEST(DeviceEmu, AnEmulatorRestartedWithOtherCapabilitiesIsRefusedUntilTheKnownOneIsBack) {
  EmuConfig cfg;
  cfg.socket_path = "/tmp/isotouch-test-emu-caps-" + std::to_string(::getpid()) + ".sock";
  cfg.caps.name = "test-emu";
  cfg.caps.max_force_n = 10;
  cfg.caps.watchdog_s = 0.05;
  struct Running {  // an emulator on its own thread until stop()
    std::unique_ptr<DeviceEmulator> emu;
    std::thread thread;
    EmuStats stats;
    explicit Running(const EmuConfig& c) : emu(std::make_unique<DeviceEmulator>(c)) {
      emu->listen();
      thread = std::thread([this] { stats = emu->run(); });
    }
    EmuStats stop() {
      emu->stop();
      thread.join();
      emu.reset();  // the socket is gone
      return stats;
    }
  };
  auto wait_for = [](auto done) {
    for (int i = 0; i < 2000 && !done(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  };
  ReportDeviceOptions opt;
  opt.reconnect_interval_s = 0.01;
  ReportDevice dev(std::make_unique<SocketLink>(cfg.socket_path), std::make_unique<V1Protocol>(), opt);
  {
    Running first(cfg);
    dev.open();
    dev.enable_force(true, 0);
    first.stop();
  }
  wait_for([&] { return dev.counters().disconnects == 1; });
  EmuConfig other = cfg;
  other.caps.max_force_n = 40;  // a stronger device on the same socket
  Running second(other);
  wait_for([&] { return dev.last_error().find("refused") != std::string::npos; });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const EmuStats refused = second.stop();
  EXPECT_NE(dev.last_error().find("the reconnected device is refused, the link stays down: maximum force [N] 40 differs from 10"),
            std::string::npos)
      << dev.last_error();
  EXPECT_EQ(dev.counters().reconnects, 0);
  EXPECT_GE(refused.connections, 1);          // it was asked for its capabilities ...
  EXPECT_EQ(refused.outputs_received, 0);     // ... and never sent a force
  EXPECT_EQ(dev.read().status, DeviceStatus::kDisconnected);
  Running known(cfg);  // the device the scene was checked against
  wait_for([&] { return dev.counters().reconnects == 1; });
  EXPECT_EQ(dev.counters().reconnects, 1);
  // The host's outputs reach it again (a keep-alive every 10 ms; the emulator may stop
  // before it reads the zero that close() sends, so that one is not counted on).
  wait_for([&] { return known.emu->stats().outputs_received > 0; });
  dev.close();
  EXPECT_GT(known.stop().outputs_received, 0);
}

/// The stall test's body, for the device speaking protocol v1 or the Polhem's reports (whose
/// "enable cleared" is zero currents).
void stalled_servo_gets_zero_within_three_periods(bool polhem) {
  Rig rig;
  rig.cfg.polhem = polhem;
  StallingWall slow;  // one tick in contact takes 300 ms
  rig.renderer = &slow;
  rig.run(1.0);  // the 300 ms stall and 200 ms of forces after it, after a servo that starts up to 150 ms late
  ASSERT_GT(slow.start_ns.load(), 0) << "the renderer never stalled";
  const std::int64_t T = 1'000'000;  // the servo's period [ns]
  // On the wire: the last force before the stall, then zero with enable cleared within
  // 3 periods of it, the host's zero first (the device's watchdog never tripped).
  const std::size_t off = rig.first_disabled_from(slow.start_ns.load());
  ASSERT_LT(off, rig.wire.size()) << "no disabled output after the renderer stalled";
  const std::size_t on = rig.last_forced_before(off);
  ASSERT_LT(on, off) << "no force before the stall";
  EXPECT_GT(norm(rig.wire[on].force_n), 0.3);
  EXPECT_LE(rig.wire[off].t_ns - rig.wire[on].t_ns, 3 * T + rig.canary.lost_ns(rig.wire[on].t_ns, rig.wire[off].t_ns))
      << "zero force came late; " << rig.canary.describe(rig.wire[on].t_ns, rig.wire[off].t_ns);
  EXPECT_EQ(norm(rig.wire[off].force_n), 0.0);
  EXPECT_EQ(rig.forced_on_wire(rig.wire[off].t_ns, slow.end_ns.load()), 0) << "force during the stall";
  EXPECT_EQ(rig.stats.watchdog_trips, 0);
  EXPECT_GE(rig.link.stalls, 1);
  // Back: the first outputs after the stall start from zero and ramp in (50 ms).
  std::size_t back = off;
  // (The Polhem has no enable flag: its first output after the stall, whatever it is.)
  while (back < rig.wire.size() && !((polhem || rig.wire[back].enable) && rig.wire[back].t_ns > slow.end_ns.load())) ++back;
  ASSERT_LT(back + 5, rig.wire.size()) << "nothing enabled after the stall";
  EXPECT_EQ(norm(rig.wire[back].force_n), 0.0) << "the late write jumped back to force";
  // The ramp: at most the wall's force with the HIP at the hand (pushed there while the
  // force was off; 10 % for overshoot) times the time since the restart (1 ms for the
  // link) over 50 ms.
  const double deepest = 500.0 * -rig.cfg.hold_m.z * 1.1;
  for (std::size_t i = back; i < back + 5; ++i)
    EXPECT_LE(norm(rig.wire[i].force_n), deepest * (double(rig.wire[i].t_ns - rig.wire[back].t_ns + 1'000'000) / 50e6))
        << "output " << i - back << " after";
  EXPECT_GT(rig.forced_on_wire(slow.end_ns.load() + 100 * T, INT64_MAX), 100) << "the force came back";
  EXPECT_GE(rig.servo_counters.late_restarts, 1);
}

TEST(DeviceEmu, AStalledServoGetsZeroForceWithEnableClearedWithinThreePeriods) {
  stalled_servo_gets_zero_within_three_periods(false);
}

TEST(DeviceEmuPolhem, AStalledServoGetsZeroCurrentsWithinThreePeriods) {
  stalled_servo_gets_zero_within_three_periods(true);
}

namespace {
void calibrated_lock_step_forces_flow(hid::polhem::Config config) {
  Rig rig;
  rig.cfg.polhem = true;
  rig.cfg.polhem_config = rig.host_config = config;
  rig.run(0.8);
  // Calibrated at once (the host answered the device's request), so the HIP is where the
  // hand holds it (3 mm into the wall): the force the emulator made of the currents it
  // received is the wall's, ~0.5 N; uncalibrated counts (400 off) would put it elsewhere.
  EXPECT_EQ(rig.stats.calibrations_lost, 0);
  EXPECT_GE(rig.stats.calibrations, 1);
  EXPECT_GT(rig.stats.calibrated_ns, 0);
  EXPECT_GT(rig.forced_ticks(), 150) << rig.summary();
  EXPECT_GT(rig.stats.max_force_n, 0.3);
  EXPECT_LT(rig.stats.max_force_n, 1.5);
  // Lock-step: one input report per command, none unasked.
  EXPECT_LE(rig.stats.reports_sent, rig.stats.outputs_received + rig.stats.calibrations);
  EXPECT_GT(rig.link.reports, 300);
  EXPECT_EQ(rig.link.garbage, 0);
  // No mismatch fault (that would be every tick). A tick or two may read the unit's first
  // report, which asks: uncalibrated until the command's answer arrives a period later.
  EXPECT_LE(rig.servo_counters.fault, 5);
}

/// A unit of one configuration driven with the other's kinematics, held at `hold` [m]:
/// once calibrated, the host faults the device (no current reaches it) and says why.
void mismatch_is_faulted(hid::polhem::Config unit, hid::polhem::Config host, const Vec3& hold,
                         const std::string& why) {
  Rig rig;
  rig.cfg.polhem = true;
  rig.cfg.polhem_config = unit;
  rig.host_config = host;
  rig.cfg.hold_m = hold;
  rig.run(1.0);  // 300 faulted ticks even after a servo that starts 500 ms late (TSan: 400 ms seen)
  EXPECT_GT(rig.stats.calibrated_ns, 0) << "never calibrated";
  EXPECT_GT(rig.servo_counters.fault, 300) << "the servo did not see the device faulted";
  long with_current = 0;
  for (const ReceivedOutput& o : rig.wire) with_current += o.t_ns > rig.stats.calibrated_ns && o.enable;
  EXPECT_EQ(with_current, 0) << "currents reached the unit after calibration";
  const std::string other = host == hid::polhem::Config::kV3 ? "config=v1" : "config=v3";
  const std::string& said = rig.last_refusal;
  EXPECT_NE(said.find(std::string("the unit is not a ") + hid::polhem::config_name(host)), std::string::npos) << said;
  EXPECT_NE(said.find(other), std::string::npos) << said;
  EXPECT_NE(said.find(why), std::string::npos) << said;
}
}  // namespace

TEST(DeviceEmuPolhem, CalibratedLockStepForcesFlowThroughThePolhemKinematics) {
  calibrated_lock_step_forces_flow(hid::polhem::Config::kV3);
  calibrated_lock_step_forces_flow(hid::polhem::Config::kV1);
}

// The v3 unit at its workspace centre reads, under polhem_v1's kinematics, about 0.33 m
// from the v1 origin (beyond the v1's reach, 0.18 m); a v1 unit 5 cm along +x is a pose the
// v3 linkage cannot close on.
TEST(DeviceEmuPolhem, AV3UnitDrivenAsAV1IsFaultedWithNoCurrent) {
  mismatch_is_faulted(hid::polhem::Config::kV3, hid::polhem::Config::kV1, Vec3{0, 0, -0.003},
                      "beyond its reach");
}

TEST(DeviceEmuPolhem, AV1UnitDrivenAsAV3IsFaultedWithNoCurrent) {
  mismatch_is_faulted(hid::polhem::Config::kV1, hid::polhem::Config::kV3, Vec3{0.05, 0, -0.003},
                      "linkage cannot close");
}

TEST(DeviceEmuPolhem, ALostCalibrationCommandIsSentAgainUntilTheDeviceStopsAsking) {
  Rig rig;
  rig.cfg.polhem = true;
  rig.cfg.polhem_lose_calibrations = 3;  // overwritten in the firmware's one-report queue
  rig.run(0.8);
  EXPECT_EQ(rig.stats.calibrations_lost, 3);
  EXPECT_GE(rig.stats.calibrations, 4) << "the command was not sent again after it was lost";
  EXPECT_GT(rig.stats.calibrated_ns, 0) << "never calibrated";
  EXPECT_GT(rig.forced_ticks(), 100) << rig.summary();
}

TEST(DeviceEmu, AFrozenWriterTripsTheDevicesWatchdog) {
  Rig rig;
  rig.while_running = [&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    rig.freeze_writes.store(true);  // the writer thread stops in its next write
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    rig.freeze_writes.store(false);
  };
  rig.run(0.6);
  // Nothing the host does reaches the device now: its own watchdog takes the force off
  // within watchdog_s (checked every device period) of the last output it received.
  ASSERT_EQ(rig.stats.watchdog_trips, 1);
  std::size_t last = 0;
  while (last + 1 < rig.wire.size() && rig.wire[last + 1].t_ns < rig.stats.first_watchdog_ns) ++last;
  const std::int64_t silence = rig.stats.first_watchdog_ns - rig.wire[last].t_ns;
  EXPECT_GE(silence, std::int64_t(rig.cfg.caps.watchdog_s * 1e9));
  EXPECT_LE(silence, std::int64_t(rig.cfg.caps.watchdog_s * 1e9) + 3'000'000 +
                        rig.canary.lost_ns(rig.wire[last].t_ns, rig.stats.first_watchdog_ns))
      << rig.canary.describe(rig.wire[last].t_ns, rig.stats.first_watchdog_ns);
  EXPECT_TRUE(rig.wire[last].enable);  // it was pushing when the writer froze
}

namespace {
StallingWall g_stuck;  // outlives the abandoned servo thread (it is inside tick() until released)
}

TEST(DeviceEmu, ARendererThatNeverReturnsIsAbandonedWithTheForceOff) {
  Rig rig;
  g_stuck.stall_ms = -1;
  g_stuck.after_ticks = 50;
  rig.renderer = &g_stuck;
  rig.run(0.8);  // 50 ticks in contact after a servo that starts up to 150 ms late (a loaded machine)
  ASSERT_GT(g_stuck.start_ns.load(), 0) << "the renderer never stuck";
  EXPECT_LT(rig.stop_s, 1.0);
  EXPECT_NE(rig.stop_error.find("the renderer has not returned"), std::string::npos) << rig.stop_error;
  const std::size_t off = rig.first_disabled_from(g_stuck.start_ns.load());
  ASSERT_LT(off, rig.wire.size()) << "no disabled output after the renderer stuck";
  const std::size_t on = rig.last_forced_before(off);
  ASSERT_LT(on, off);
  EXPECT_LE(rig.wire[off].t_ns - rig.wire[on].t_ns, 3'000'000 + rig.canary.lost_ns(rig.wire[on].t_ns, rig.wire[off].t_ns))
      << rig.canary.describe(rig.wire[on].t_ns, rig.wire[off].t_ns);
  EXPECT_EQ(rig.forced_on_wire(rig.wire[off].t_ns, INT64_MAX), 0) << "force after the renderer stuck";
  // The abandoned thread, released, leaves without touching the (destroyed) servo or device.
  g_stuck.release.store(true);
  while (g_stuck.end_ns.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

// The Polhem from power-up, as its firmware starts (forsslund/haptikfabrikenapi
// firmware/main.cpp): info 0 (the switch's latched flag starts clear), counters 0 where it
// powered up, and any current it is sent driven. The host must send none until it has
// answered the switch's request (info 1) with the calibration command and seen info 0 again;
// then the force flows from the calibrated counts. Asserted on what the unit received.
TEST(DeviceEmuPolhem, FromPowerUpNoCurrentReachesTheUnitUntilItIsCalibrated) {
  Rig rig;
  rig.cfg.polhem = true;
  rig.cfg.polhem_power_up = true;
  rig.cfg.polhem_switch_at_s = 0.5;  // the handle pressed into the calibration switch
  // polhem_v1: its counts solve back to the power-up pose below (encoders_for, the emulator's
  // inverse kinematics, finds another branch of the v3 linkage that far out).
  const hid::polhem::Config c = rig.cfg.polhem_config = rig.host_config = hid::polhem::Config::kV1;
  // Where it powered up (140 mm back, at the height of the v1's origin): chosen so that, with
  // the hand holding the handle at hold_m, its counters read a pose inside the workspace 10 mm
  // into the wall. A host that took info 0 as calibrated would render the wall there (its
  // 5 N limit) and the unit would push.
  const Vec3 seen{0, 0, -0.010};
  const auto at_hold = hid::polhem::encoders_for(rig.cfg.hold_m, c), reads = hid::polhem::encoders_for(seen, c);
  std::array<std::int16_t, 6> zero{};
  for (std::size_t i = 0; i < 3; ++i) zero[i] = std::int16_t(at_hold[i] - reads[i]);
  rig.cfg.polhem_power_up_m = hid::polhem::position_m(zero, c);
  {  // the premise: those counters read `seen` (and a pose the servo would render)
    const auto z = hid::polhem::encoders_for(*rig.cfg.polhem_power_up_m, c);
    std::array<std::int16_t, 6> e{};
    for (std::size_t i = 0; i < 3; ++i) e[i] = std::int16_t(at_hold[i] - z[i]);
    ASSERT_LT(norm(hid::polhem::position_m(e, c) - seen), 0.001);
    ASSERT_TRUE(hid::polhem::caps(c).contains(seen));
  }
  std::string said_before;  // the device's last refusal while it waits for the press
  rig.while_running = [&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(350));
    said_before = rig.dev->last_refusal();
  };
  rig.run(1.2);  // 0.5 s before the press, 0.7 s after
  ASSERT_EQ(rig.stats.switch_presses, 1);
  ASSERT_GT(rig.stats.calibrated_ns, 0) << "never calibrated: " << rig.summary();
  EXPECT_GE(rig.stats.calibrated_ns - rig.stats.start_ns, 500'000'000) << "calibrated before the switch was pressed";
  EXPECT_EQ(rig.stats.calibrations_lost, 0);
  // Before calibration: no current reached the unit, by its own count and on the wire.
  EXPECT_EQ(rig.stats.currents_while_uncalibrated, 0) << rig.summary();
  EXPECT_EQ(rig.forced_on_wire(0, rig.stats.calibrated_ns), 0) << "current on the wire before calibration";
  // Waiting for calibration is no fault (`isotouch run --live` does not exit 5 for it).
  EXPECT_GT(rig.servo_counters.uncalibrated, 200) << "the servo did not see the unit uncalibrated: " << rig.summary();
  EXPECT_EQ(rig.servo_counters.fault, 0) << rig.summary();
  EXPECT_NE(said_before.find("not calibrated since isotouch opened it"), std::string::npos) << said_before;
  // Calibrated since: the reason no longer holds and is not kept as the last refusal.
  EXPECT_EQ(rig.last_refusal, "") << "kept after the calibration";
  EXPECT_EQ(rig.last_error.find("not calibrated"), std::string::npos) << rig.last_error;
  // The servo ramped in from zero once calibrated (50 ms): at most the wall's force at the
  // hand (10 % for overshoot) times the time since the first calibrated tick (1 ms slack).
  std::size_t ok = 0;
  const std::size_t n = rig.log.n.load();
  while (ok < n && rig.log.status[ok] != DeviceStatus::kOk) ++ok;
  ASSERT_LT(ok + 5, n) << rig.summary();
  for (std::size_t i = 0; i < ok; ++i) EXPECT_EQ(rig.log.force[i], 0.0) << "tick " << i << " before calibration";
  const double deepest = 500.0 * -rig.cfg.hold_m.z * 1.1;
  for (std::size_t i = ok; i < ok + 5; ++i)
    EXPECT_LE(rig.log.force[i], deepest * (double(rig.log.t_ns[i] - rig.log.t_ns[ok] + 1'000'000) / 50e6))
        << "tick " << i - ok << " after calibration";
  // After: the wall's force at the hand's true pose, 3 mm in (~0.5 N; the uncalibrated
  // reading, 10 mm in, would be the 5 N limit).
  EXPECT_GT(rig.forced_on_wire(rig.stats.calibrated_ns, INT64_MAX), 300) << rig.summary();
  EXPECT_GT(rig.stats.max_force_n, 0.3);
  EXPECT_LT(rig.stats.max_force_n, 1.5);
}

// A v1 device applies the force it is sent once per report period (docs/hid-protocol.md,
// capabilities bytes 4-5): a servo faster than its declared report rate is refused before it
// writes (its ticks between two reports would be lost, and read stale), as for the SDK
// devices' own loops; at the declared rate it runs. The emulator is the device here.
TEST(DeviceEmu, AServoFasterThanTheDeclaredReportRateIsRefused) {
  EmuConfig cfg;
  cfg.socket_path = "/tmp/isotouch-test-emu-rate-" + std::to_string(::getpid()) + ".sock";
  cfg.rate_hz = 500;
  cfg.seconds = 0;  // until stop()
  cfg.caps.name = "test-emu";
  cfg.caps.max_force_n = 10;
  cfg.caps.native_rate_hz = cfg.rate_hz;
  cfg.caps.watchdog_s = 0.05;
  DeviceEmulator emu(cfg);
  emu.listen();
  std::thread emu_thread([&] { emu.run(); });
  ReportDevice dev(std::make_unique<SocketLink>(cfg.socket_path), std::make_unique<V1Protocol>());
  dev.open();
  EXPECT_DOUBLE_EQ(dev.caps().output_rate_hz, 500);
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.016})));
  Wall wall;
  ServoThreadConfig sc;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = false;
  sc.rate_hz = 1000;
  std::string refusal;
  {
    ServoThread servo(published, wall, dev, sc);
    try {
      servo.start();
    } catch (const std::invalid_argument& e) {
      refusal = e.what();
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(30));  // a write would be on the wire by now
  const auto enabled = [&] {
    long n = 0;
    for (const ReceivedOutput& o : emu.output_log()) n += o.enable ? 1 : 0;
    return n;
  };
  const long before = enabled();
  sc.rate_hz = 500;
  {
    ServoThread servo(published, wall, dev, sc);
    servo.start();
    // 11 enabled outputs, however long a loaded machine takes for them (20 s at most).
    for (int i = 0; i < 2000 && enabled() <= 10; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    servo.stop();
  }
  dev.close();
  emu.stop();
  emu_thread.join();
  EXPECT_NE(refusal.find("above test-emu's own output loop (500"), std::string::npos) << "refusal: '" << refusal << "'";
  EXPECT_EQ(before, 0) << "the refused servo enabled the device's force";
  EXPECT_GT(enabled(), 10) << "the servo at the device's rate sent nothing";
}
