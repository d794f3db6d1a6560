// End to end against the device emulator in real time at 1 kHz: the servo thread drives a
// ReportDevice over the socket link to a DeviceEmulator (protocol v1) whose simulated hand
// presses into a penalty wall. Disconnect (the emulator gone) -> zero force within one tick;
// freeze -> zero force after the stale timeout; garbage -> counted and named, no crash;
// reconnect -> the force ramps in again; sequence faults counted.
#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <memory>
#include <thread>

#include "analytic_fields.h"
#include "device_emulator.h"
#include "device_protocols.h"
#include "report_device.h"
#include "servo_thread.h"
#include "socket_link.h"

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
  TickLog log;
  EmuStats stats;
  DeviceCounters servo_counters;
  LinkCounters link;
  std::string last_error, last_refusal;

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
    emu = std::make_unique<DeviceEmulator>(cfg);
    emu->listen();
    std::thread emu_thread([this] { stats = emu->run(); });
    dev = std::make_unique<ReportDevice>(std::make_unique<SocketLink>(cfg.socket_path), std::make_unique<V1Protocol>());
    dev->open();
    ServoThreadConfig sc;
    sc.rate_hz = 1000;
    sc.sched_fifo = sc.pin_cpu = sc.lock_memory = false;
    sc.observer = &log;
    {
      ServoThread servo(published, wall, *dev, sc);
      servo.start();
      emu_thread.join();
      servo.stop();
      servo_counters = servo.device_counters();
    }
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
};
}  // namespace

TEST(DeviceEmu, TheHandPressesAndTheForceFlowsBothWays) {
  Rig rig;
  rig.run(0.4);
  EXPECT_GT(rig.forced_ticks(), 150);                         // the wall pushed back
  // Forces reached the device: most ticks' outputs arrived (relative to the ticks the servo
  // ran, which a loaded machine or a sanitizer build makes fewer than 400 in 0.4 s).
  EXPECT_GT(rig.stats.outputs_received, 150);
  EXPECT_GT(double(rig.stats.outputs_received), 0.75 * double(rig.log.n.load()));
  EXPECT_GT(rig.stats.max_force_n, 0.3);
  EXPECT_LT(rig.stats.max_force_n, 1.5);
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
  // Forces came back after the freeze.
  EXPECT_GT(rig.forced_after(rig.log.t_ns[0] + 350'000'000), 50);
}

TEST(DeviceEmu, GarbageIsCountedAndNamedWithoutACrash) {
  Rig rig;
  rig.cfg.faults.garbage = 0.1;
  rig.run(0.4);
  EXPECT_GT(rig.link.garbage, 15);
  EXPECT_NE(rig.last_refusal.find("refused input report"), std::string::npos) << rig.last_refusal;
  EXPECT_GT(rig.forced_ticks(), 100);  // the good reports kept the force going
}

TEST(DeviceEmu, ReconnectionRampsTheForceIn) {
  Rig rig;
  rig.cfg.faults.disconnect_at_s = 0.15;
  rig.cfg.faults.reconnect_after_s = 0.1;
  rig.run(0.6);
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
}

TEST(DeviceEmu, SequenceFaultsAreCounted) {
  Rig rig;
  rig.cfg.faults.drop = 0.05;
  rig.cfg.faults.duplicate = 0.05;
  rig.cfg.faults.reorder = 0.05;
  rig.cfg.faults.delay = 0.02;
  rig.run(0.4);
  EXPECT_GT(rig.link.gaps, 5);
  EXPECT_GT(rig.link.duplicates, 5);
  EXPECT_GT(rig.link.reordered, 5);
  EXPECT_GT(rig.forced_ticks(), 200);
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
    dev.enable_force(true);
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
  dev.close();
  EXPECT_GT(known.stop().outputs_received, 0);
}
