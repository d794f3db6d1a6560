// Vendor SDK backends against the test doubles of their libraries (tests/sdk_doubles):
// what the double RECEIVED (its SDK's units and frame) is the truth, not what the backend
// says it sent.
#include <dlfcn.h>
#include <pthread.h>
#include <gtest/gtest.h>
#include <stdlib.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <thread>
#include <vector>

#include "isotouch/servo/forcedimension_device.h"
#include "isotouch/servo/openhaptics_device.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/triple_buffer.h"

using namespace isotouch;
using servo::DeviceStatus;
using Vec3 = core::Vec3;

namespace {
void sleep_ms(double ms) { std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(ms)); }

using Rows = std::vector<std::array<double, 5>>;

/// What both doubles export for tests: their log of received forces.
struct DoubleLog {
  int (*log)(double*, int) = nullptr;
  /// Rows of (t_s, fx, fy, fz [N, the SDK's frame], flags).
  Rows received() const {
    Rows rows(1 << 16);
    const int n = log(rows.front().data(), int(rows.size()));
    rows.resize(std::size_t(std::min<int>(n, int(rows.size()))));
    return rows;
  }
};

/// The double's test controls, from the library the backend loaded.
struct HdControls : DoubleLog {
  void (*vanish)(int);
  void (*set_target)(const double*);
  void (*clear_log)();
  long (*illegal)();
  int (*force_output)();
  void (*inkwell)();
  long (*calibration_updates)();
  long (*calibration_updates_off_scheduler)();
  HdControls() {
    void* h = dlopen(HD_DOUBLE, RTLD_NOW | RTLD_GLOBAL);
    if (!h) throw std::runtime_error(dlerror());
    vanish = reinterpret_cast<void (*)(int)>(dlsym(h, "hdDoubleVanish"));
    set_target = reinterpret_cast<void (*)(const double*)>(dlsym(h, "hdDoubleSetTarget"));
    log = reinterpret_cast<int (*)(double*, int)>(dlsym(h, "hdDoubleLog"));
    clear_log = reinterpret_cast<void (*)()>(dlsym(h, "hdDoubleClearLog"));
    illegal = reinterpret_cast<long (*)()>(dlsym(h, "hdDoubleIllegalCalls"));
    force_output = reinterpret_cast<int (*)()>(dlsym(h, "hdDoubleForceOutput"));
    inkwell = reinterpret_cast<void (*)()>(dlsym(h, "hdDoubleInkwell"));
    calibration_updates = reinterpret_cast<long (*)()>(dlsym(h, "hdDoubleCalibrationUpdates"));
    calibration_updates_off_scheduler = reinterpret_cast<long (*)()>(dlsym(h, "hdDoubleCalibrationUpdatesOffScheduler"));
  }
};

struct OpenHaptics : ::testing::Test {
  void SetUp() override { setenv("ISOTOUCH_HD_LIBRARY", HD_DOUBLE, 1); }
  HdControls ctl;
};

/// Polls `done` every ms for at most `ms` milliseconds (a loaded machine is slow, not wrong).
template <class F>
bool wait_for(F done, int ms = 2000) {
  for (int i = 0; i < ms; ++i, sleep_ms(1))
    if (done()) return true;
  return done();
}

/// The stall time the tests give while they check that forces pass: long enough for a test
/// thread starved on a loaded machine; the stall tests then wait past it.
constexpr double kTestStallS = 0.2;

/// The forces received after the first one received while the device had vanished.
Rows forces_after_vanish(const Rows& rows) {
  Rows out;
  bool gone = false;
  for (const auto& r : rows) {
    if (gone) out.push_back(r);
    if (int(r[4]) & 2) gone = true;
  }
  return out;
}

/// Writes `f` every ms for `ms` milliseconds, as the servo thread would (reading first unless
/// another thread reads: read() and write_force_n() are each one thread's).
void write_for(servo::HapticDeviceIO& d, const Vec3& f, int ms, bool read = true) {
  for (int i = 0; i < ms; ++i) {
    if (read) d.read();
    d.write_force_n(f);
    sleep_ms(1);
  }
}
/// The servo stops writing: an exact zero once the stall time passed, counted once; then,
/// closed while the servo writes, an exact zero is the last force the double received.
template <class Device, class Controls>
void check_stall_then_close(Device& d, Controls& ctl, const std::atomic<std::uint64_t>& stalls) {
  const std::uint64_t s0 = stalls.load();
  ctl.clear_log();
  ASSERT_TRUE(wait_for([&] { return stalls.load() == s0 + 1; }));
  sleep_ms(20);
  const auto zero = [&](const char* when) {
    const auto r = ctl.received().back();
    EXPECT_TRUE(r[1] == 0.0 && r[2] == 0.0 && r[3] == 0.0) << when << ": " << r[1] << ", " << r[2] << ", " << r[3];
  };
  zero("after the stall");
  EXPECT_EQ(stalls.load(), s0 + 1);
  write_for(d, {1.0, 2.0, -0.5}, 20);
  d.close();
  zero("after close");
}

/// The device vanishes while the servo pushes along isotouch x (0.5 N): the reading says
/// disconnected, the SDK's error is named, every force the double received after the first
/// one sent to the vanished device is an exact zero (`column`: the SDK axis x maps to), and
/// the device back is a new connection (the servo ramps in). Closes the device.
template <class Device, class Controls>
void check_vanish(Device& d, Controls& ctl, int column, const std::string& error) {
  d.enable_force(true, kTestStallS);
  write_for(d, {0.5, 0, 0}, 20);
  ctl.clear_log();
  ctl.vanish(1);
  std::thread servo([&] { write_for(d, {0.5, 0, 0}, 40, false); });
  EXPECT_TRUE(wait_for([&] { return d.read().status == DeviceStatus::kDisconnected; }));
  servo.join();
  EXPECT_NE(d.last_error().find(error), std::string::npos) << d.last_error();
  EXPECT_TRUE(wait_for([&] { return forces_after_vanish(ctl.received()).size() > 10; }));
  for (const auto& r : forces_after_vanish(ctl.received()))
    EXPECT_EQ(r[std::size_t(column)], 0.0) << "force after the device vanished, t " << r[0];
  const std::uint32_t conn = d.read().connection;
  ctl.vanish(0);
  EXPECT_TRUE(wait_for([&] { return d.read().status == DeviceStatus::kOk; }));
  EXPECT_EQ(d.read().connection, conn + 1) << "a device back is a new connection (the servo ramps in)";
  d.close();
}
}  // namespace

TEST(OpenHapticsLoad, MissingLibraryNamesWhatWasSearched) {
  setenv("ISOTOUCH_HD_LIBRARY", "/nonexistent/libHD.so", 1);
  servo::OpenHapticsDevice d;
  try {
    d.open();
    FAIL() << "opened without the library";
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("OpenHaptics HD library not found"), std::string::npos) << m;
    EXPECT_NE(m.find("searched: $ISOTOUCH_HD_LIBRARY=/nonexistent/libHD.so"), std::string::npos) << m;
  }
  unsetenv("ISOTOUCH_HD_LIBRARY");
  servo::HdApi api;
  const std::string e = servo::load_hd_api(api);
  if (!api.lib) {
    EXPECT_NE(e.find("ISOTOUCH_HD_LIBRARY unset; libHD.so: "), std::string::npos) << e;
  }
}

TEST_F(OpenHaptics, UnknownDeviceNameGivesTheHdError) {
  servo::OpenHapticsDevice d("no such arm");
  try {
    d.open();
    FAIL() << "opened a device that does not exist";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("hdInitDevice: HD_COMM_CONFIG_ERROR (0x303"), std::string::npos) << e.what();
  }
}

TEST_F(OpenHaptics, CapabilitiesAndPoseInIsotouchFrame) {
  servo::OpenHapticsDevice d;
  d.open();
  const servo::DeviceCaps c = d.caps();
  EXPECT_DOUBLE_EQ(c.max_force_n, 3.3);
  EXPECT_DOUBLE_EQ(c.max_stiffness_n_per_m, 1000.0);  // 1.0 N/mm
  EXPECT_DOUBLE_EQ(c.max_damping_n_s_per_m, 5.0);     // 0.005 N s/mm
  EXPECT_DOUBLE_EQ(c.native_rate_hz, 1000);
  // HD box x +-190, y +-130, z +-95 mm -> x +-0.19, y (= -z) +-0.095, z (= y) +-0.13 m.
  EXPECT_NEAR(c.workspace_min_m.y, -0.095, 1e-12);
  EXPECT_NEAR(c.workspace_max_m.z, 0.13, 1e-12);
  EXPECT_NE(d.description().find("calibration ok"), std::string::npos) << d.description();
  const double target_mm[3] = {10, 20, 30};  // HD: right, up, toward the user
  ctl.set_target(target_mm);
  sleep_ms(600);
  const servo::DeviceReading r = d.read();
  EXPECT_EQ(r.status, DeviceStatus::kOk);
  EXPECT_NEAR(r.position_m.x, 0.010, 2e-4);   // right
  EXPECT_NEAR(r.position_m.y, -0.030, 2e-4);  // toward the user = -y
  EXPECT_NEAR(r.position_m.z, 0.020, 2e-4);   // up
  EXPECT_GT(r.received_ns, 0);
  d.close();
  EXPECT_EQ(ctl.illegal(), 0) << "HD calls outside the scheduler's frames";
}

TEST_F(OpenHaptics, ForcesArriveInHdFrameAndStopAtExactZero) {
  servo::OpenHapticsDevice d;
  d.open();
  const auto* stalls = d.enable_force(true, kTestStallS);
  ctl.clear_log();
  write_for(d, {1.0, 2.0, -0.5}, 50);  // isotouch: right, away from the user, down
  auto rows = ctl.received();
  ASSERT_GT(rows.size(), 30u);
  const auto& last = rows.back();
  EXPECT_EQ(int(last[4]) & 1, 1) << "force output not enabled";
  EXPECT_DOUBLE_EQ(last[1], 1.0);   // HD x: right
  EXPECT_DOUBLE_EQ(last[2], -0.5);  // HD y: up
  EXPECT_DOUBLE_EQ(last[3], -2.0);  // HD z: toward the user
  check_stall_then_close(d, ctl, *stalls);
  EXPECT_EQ(ctl.illegal(), 0);
}

// close() leaves HD_FORCE_OUTPUT disabled in the library (what the driver holds), after an
// exact zero was the last force applied.
TEST_F(OpenHaptics, CloseDisablesForceOutput) {
  servo::OpenHapticsDevice d;
  d.open();
  EXPECT_EQ(ctl.force_output(), 1) << "open() enables force output";
  d.enable_force(true, kTestStallS);
  write_for(d, {0.5, 0, 0}, 20);
  d.close();
  EXPECT_EQ(ctl.force_output(), 0) << "close() left HD_FORCE_OUTPUT enabled";
  const auto r = ctl.received().back();
  EXPECT_TRUE(r[1] == 0.0 && r[2] == 0.0 && r[3] == 0.0);
}

// Non-finite forces written by the servo never reach the device: the double's own limit
// check lets NaN through (NaN > max is false), so what it received is the backend's backstop.
TEST_F(OpenHaptics, ANonFiniteForceReachesTheDeviceAsAnExactZero) {
  servo::OpenHapticsDevice d;
  d.open();
  d.enable_force(true, kTestStallS);
  ctl.clear_log();
  const double inf = std::numeric_limits<double>::infinity();
  for (const Vec3 bad : {Vec3{NAN, 0, 0}, Vec3{0, inf, 0}, Vec3{0, 0, -inf}}) write_for(d, bad, 15);
  const auto rows = ctl.received();
  ASSERT_GT(rows.size(), 20u);
  for (const auto& r : rows)
    EXPECT_TRUE(r[1] == 0.0 && r[2] == 0.0 && r[3] == 0.0) << "t " << r[0] << ": " << r[1] << ", " << r[2] << ", " << r[3];
  d.close();
}

// The continuous force and the scheduler's rate are read; a servo faster than the scheduler
// applies forces is refused by the servo thread (its ticks between frames would be lost).
TEST_F(OpenHaptics, ContinuousForceAndOutputRateAreRead) {
  servo::OpenHapticsDevice d;
  d.open();
  const servo::DeviceCaps c = d.caps();
  EXPECT_DOUBLE_EQ(c.max_continuous_force_n, 0.88);
  EXPECT_DOUBLE_EQ(c.output_rate_hz, 1000);
  // 2.5 servo periods less half a device period: the force is off within 3 periods.
  d.enable_force(true, 0.0025);
  EXPECT_EQ(d.stall_ns(), 2'000'000);
  d.close();
}

// A calibration that needs an update is updated from the HD scheduler (as the SDK's
// Calibration example does), in the automatic style the device offers; until it is ok every
// reading is a fault and the device gets zero force.
TEST_F(OpenHaptics, ACalibrationThatNeedsAnUpdateIsUpdatedBeforeAnyForce) {
  setenv("HD_DOUBLE_CALIBRATION", "update", 1);
  servo::OpenHapticsDevice d;
  d.open();
  unsetenv("HD_DOUBLE_CALIBRATION");
  EXPECT_NE(d.warning().find("needs update"), std::string::npos) << d.warning();
  EXPECT_TRUE(wait_for([&] { return d.calibrated(); }));
  EXPECT_GE(ctl.calibration_updates(), 1);
  EXPECT_EQ(ctl.calibration_updates_off_scheduler(), 0) << "hdUpdateCalibration called off the scheduler";
  EXPECT_TRUE(wait_for([&] { return d.read().status == DeviceStatus::kOk; }));
  d.enable_force(true, kTestStallS);
  ctl.clear_log();
  write_for(d, {0.5, 0, 0}, 30);
  EXPECT_EQ(ctl.received().back()[1], 0.5);
  d.close();
}

// A device that needs the stylus in its inkwell, or whose calibration never gets ok: no force
// reaches it (every row the double received is an exact zero) and readings are uncalibrated
// (not faults), until the stylus is put in the inkwell.
TEST_F(OpenHaptics, NoForceUntilTheCalibrationIsOk) {
  setenv("HD_DOUBLE_CALIBRATION", "manual", 1);
  servo::OpenHapticsDevice d;
  d.open();
  unsetenv("HD_DOUBLE_CALIBRATION");
  EXPECT_NE(d.warning().find("manual input"), std::string::npos) << d.warning();
  d.enable_force(true, kTestStallS);
  ctl.clear_log();
  write_for(d, {0.5, 0, 0}, 60);
  EXPECT_EQ(d.read().status, DeviceStatus::kUncalibrated);  // zero force, not a fault
  EXPECT_TRUE(d.read().force_off);
  EXPECT_FALSE(d.calibrated());
  auto rows = ctl.received();
  ASSERT_GT(rows.size(), 30u);
  for (const auto& r : rows) EXPECT_EQ(r[1], 0.0) << "a force reached an uncalibrated device at t " << r[0];
  ctl.inkwell();
  EXPECT_TRUE(wait_for([&] { return d.calibrated(); }));
  write_for(d, {0.5, 0, 0}, 30);
  EXPECT_EQ(ctl.received().back()[1], 0.5);
  d.close();
}

namespace {
/// Pushes along isotouch x wherever the HIP is (a hand leaning into a wall).
class Push final : public servo::Renderer {
 public:
  const char* name() const override { return "push"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView&, const Vec3&, double) override {
    servo::HriTick t;
    t.force_n = {0.5, 0, 0};
    t.contact = true;
    return t;
  }
};
}  // namespace

// Calibrated only after the servo started (the stylus put in its inkwell after 60 frames): until
// then every force the double received is an exact zero and the servo counts the ticks as
// uncalibrated, not as faults (`isotouch run --live` does not exit 5 for it); once calibrated
// the force ramps in (50 ms) to the renderer's 0.5 N, what the double received.
TEST_F(OpenHaptics, CalibratedAfterTheStartTheForceRampsInAndNoFaultIsCounted) {
  setenv("HD_DOUBLE_CALIBRATION", "manual", 1);
  servo::OpenHapticsDevice d;
  d.open();
  unsetenv("HD_DOUBLE_CALIBRATION");
  servo::TripleBuffer<core::SampleField> none;  // the push reads no field
  none.publish(std::make_shared<const core::SampleField>());
  Push push;
  servo::ServoThreadConfig sc;
  sc.rate_hz = 1000;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = false;
  sc.ramp_in_s = 0.05;
  servo::ServoThread servo(none, push, d, sc);
  ctl.clear_log();
  servo.start();
  // Uncalibrated for 60 device frames and 60 servo ticks, however long a loaded machine takes
  // for them (a fixed sleep gave too few).
  ASSERT_TRUE(wait_for([&] { return ctl.received().size() > 60 && servo.device_counters().uncalibrated > 60; }, 20000))
      << "the device and the servo did not run";
  EXPECT_EQ(servo.device_status(), DeviceStatus::kUncalibrated);
  const std::size_t before = ctl.received().size();
  ctl.inkwell();
  EXPECT_TRUE(wait_for([&] { return d.calibrated(); }));
  EXPECT_TRUE(wait_for([&] { return ctl.received().back()[1] == 0.5; })) << "the force never came";
  servo.stop();
  const servo::DeviceCounters c = servo.device_counters();
  EXPECT_EQ(c.fault, 0) << "waiting for calibration counted as a fault";
  EXPECT_GT(c.uncalibrated, 50);
  const Rows rows = ctl.received();
  ASSERT_GT(before, 50u);
  for (std::size_t i = 0; i < before; ++i)
    EXPECT_EQ(rows[i][1], 0.0) << "a force reached the uncalibrated device at t " << rows[i][0];
  // The ramp: the first forces after calibration rise from zero, over about 50 ms.
  std::size_t first = before;
  while (first < rows.size() && rows[first][1] == 0.0) ++first;
  ASSERT_LT(first, rows.size());
  EXPECT_LT(rows[first][1], 0.1) << "the force stepped in";
  // It rose over the ramp's time (50 ms; judged at half of it, so late ticks at either end do
  // not count), not in a few frames: on the frames' times, so a starved device thread that ran
  // fewer frames still passes.
  std::size_t full = first;
  while (full < rows.size() && rows[full][1] < 0.5) ++full;
  ASSERT_LT(full, rows.size()) << "the force never reached 0.5 N";
  EXPECT_GE(rows[full][0] - rows[first][0], 0.025) << "no ramp: the force came in within "
                                                   << (rows[full][0] - rows[first][0]) * 1e3 << " ms";
}

TEST_F(OpenHaptics, VanishedDeviceReadsDisconnectedAndGetsZero) {
  servo::OpenHapticsDevice d;
  d.open();
  check_vanish(d, ctl, 1, "HD_COMM_ERROR");  // a force along isotouch x is HD x
}

namespace {
struct DhdControls : DoubleLog {
  void (*vanish)(int);
  void (*set_target)(const double*);
  void (*clear_log)();
  long (*calls_on)(unsigned long);
  int (*force_on)();
  int (*watchdog)();
  long (*opens)();
  void (*arm_watchdog)(int);
  void (*starve)(int);
  void (*force_button)(int);
  long (*watchdog_trips)();
  long (*enables)();
  DhdControls() {
    void* h = dlopen(DHD_DOUBLE, RTLD_NOW | RTLD_GLOBAL);
    if (!h) throw std::runtime_error(dlerror());
    vanish = reinterpret_cast<void (*)(int)>(dlsym(h, "dhdDoubleVanish"));
    set_target = reinterpret_cast<void (*)(const double*)>(dlsym(h, "dhdDoubleSetTarget"));
    log = reinterpret_cast<int (*)(double*, int)>(dlsym(h, "dhdDoubleLog"));
    clear_log = reinterpret_cast<void (*)()>(dlsym(h, "dhdDoubleClearLog"));
    calls_on = reinterpret_cast<long (*)(unsigned long)>(dlsym(h, "dhdDoubleCallsOn"));
    force_on = reinterpret_cast<int (*)()>(dlsym(h, "dhdDoubleForceOn"));
    watchdog = reinterpret_cast<int (*)()>(dlsym(h, "dhdDoubleWatchdog"));
    opens = reinterpret_cast<long (*)()>(dlsym(h, "dhdDoubleOpens"));
    arm_watchdog = reinterpret_cast<void (*)(int)>(dlsym(h, "dhdDoubleArmWatchdog"));
    starve = reinterpret_cast<void (*)(int)>(dlsym(h, "dhdDoubleStarve"));
    force_button = reinterpret_cast<void (*)(int)>(dlsym(h, "dhdDoubleForceButton"));
    watchdog_trips = reinterpret_cast<long (*)()>(dlsym(h, "dhdDoubleWatchdogTrips"));
    enables = reinterpret_cast<long (*)()>(dlsym(h, "dhdDoubleEnables"));
  }
};

struct ForceDimension : ::testing::Test {
  void SetUp() override { setenv("ISOTOUCH_DHD_LIBRARY", DHD_DOUBLE, 1); }
  void TearDown() override { ctl.arm_watchdog(0); }
  DhdControls ctl;
};

/// A servo on its own thread, as ServoThread treats the reading's force_off: holds its force
/// at an exact zero (its ramp at 0) while the device says its force is off, else pushes
/// `push`; counts the readings that said the watchdog tripped.
struct FdServo {
  servo::HapticDeviceIO& d;
  Vec3 push;
  std::atomic<bool> stop{false};
  std::atomic<long> tripped{0};
  std::thread thread{[this] {
    while (!stop.load()) {
      const servo::DeviceReading r = d.read();
      if (r.watchdog_tripped) tripped.fetch_add(1);
      d.answer(r.sequence);
      d.write_force_n(r.force_off ? Vec3{} : push);
      sleep_ms(0.5);
    }
  }};
  ~FdServo() { end(); }
  void end() {
    stop = true;
    if (thread.joinable()) thread.join();
  }
};

/// The index of the first row at or after `from` that the double received with forces on
/// after one with forces off (rows.size(): none).
std::size_t first_on_after_off(const Rows& rows, std::size_t from = 0) {
  bool off = false;
  for (std::size_t i = from; i < rows.size(); ++i) {
    if (!(int(rows[i][4]) & 1)) off = true;
    else if (off) return i;
  }
  return rows.size();
}
}  // namespace

TEST(ForceDimensionLoad, MissingLibraryNamesWhatWasSearched) {
  setenv("ISOTOUCH_DHD_LIBRARY", "/nonexistent/libdhd.so", 1);
  servo::ForceDimensionDevice d;
  try {
    d.open();
    FAIL() << "opened without the library";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("Force Dimension SDK library not found (searched: $ISOTOUCH_DHD_LIBRARY=/nonexistent/libdhd.so"),
              std::string::npos)
        << e.what();
  }
}

TEST_F(ForceDimension, IndexBeyondTheDevicesIsRefused) {
  servo::ForceDimensionDevice d(3);
  try {
    d.open();
    FAIL() << "opened device 3 of 1";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("forcedimension:3: no such device (1 found"), std::string::npos) << e.what();
  }
}

TEST_F(ForceDimension, PoseAndForcesInFdFrameFromADeviceThread) {
  servo::ForceDimensionDevice d(0, 2000);
  d.open();
  const servo::DeviceCaps c = d.caps();
  EXPECT_EQ(c.name, "delta.3");  // system type 63, CHAI3D's limits
  EXPECT_DOUBLE_EQ(c.max_force_n, 20.0);
  EXPECT_DOUBLE_EQ(c.max_stiffness_n_per_m, 5000.0);
  EXPECT_DOUBLE_EQ(c.workspace_max_m.x, 0.15);
  const double target[3] = {0.01, 0.02, 0.03};  // FD: toward the user, right, up [m]
  ctl.set_target(target);
  sleep_ms(600);
  const servo::DeviceReading r = d.read();
  EXPECT_EQ(r.status, DeviceStatus::kOk);
  EXPECT_NEAR(r.position_m.x, 0.02, 2e-4);   // right
  EXPECT_NEAR(r.position_m.y, -0.01, 2e-4);  // toward the user = -y
  EXPECT_NEAR(r.position_m.z, 0.03, 2e-4);   // up
  const auto* stalls = d.enable_force(true, kTestStallS);
  ctl.clear_log();
  write_for(d, {1.0, 2.0, -0.5}, 50);
  auto rows = ctl.received();
  ASSERT_GT(rows.size(), 30u);
  EXPECT_EQ(int(rows.back()[4]) & 1, 1) << "force not enabled";
  EXPECT_DOUBLE_EQ(rows.back()[1], -2.0);  // FD x: toward the user = -y
  EXPECT_DOUBLE_EQ(rows.back()[2], 1.0);   // FD y: right
  EXPECT_DOUBLE_EQ(rows.back()[3], -0.5);  // FD z: up
  EXPECT_EQ(ctl.calls_on(static_cast<unsigned long>(pthread_self())), 0) << "a dhd call on the servo's thread";
  check_stall_then_close(d, ctl, *stalls);
  EXPECT_EQ(ctl.force_on(), 0) << "force left enabled at close";
}

// open() sets the firmware's watchdog (what the double's firmware holds: 125 us units), so a
// killed isotouch leaves no force on: 10 ms at 2 kHz (10 periods would be 5 ms); the device
// thread's rate is its output rate (a faster servo is refused).
TEST_F(ForceDimension, OpenSetsTheFirmwareWatchdog) {
  servo::ForceDimensionDevice d(0, 2000);
  d.open();
  EXPECT_EQ(ctl.watchdog(), 80) << "10 ms in 125 us units";
  EXPECT_DOUBLE_EQ(d.watchdog_s(), 0.010);
  EXPECT_DOUBLE_EQ(d.caps().output_rate_hz, 2000);
  EXPECT_NE(d.description().find("firmware watchdog 10 ms"), std::string::npos) << d.description();
  d.close();
}

TEST_F(ForceDimension, VanishedDeviceReadsDisconnectedAndGetsZero) {
  servo::ForceDimensionDevice d(0, 2000);
  const long opens = ctl.opens();
  d.open();
  // The double's ID stays invalid after the device is back (as the SDK's): back only because
  // the device thread closed it and opened the index again.
  check_vanish(d, ctl, 2, "dhdGetPosition failed: communication error");  // isotouch x is FD y
  EXPECT_GE(d.reopens(), 1);
  EXPECT_EQ(ctl.opens(), opens + 1 + d.reopens());
}

// The device thread starves 25 ms (the double's dhdGetPosition blocks) past the firmware's
// 10 ms watchdog, which turns the forces off. The device thread reads that from dhdGetStatus
// (DHD_STATUS_FORCE 0, DHD_STATUS_FORCEOFFCAUSE DHD_FORCEOFF_WATCHDOG: the double's literal
// vendor values): its readings say force_off and watchdog_tripped (the servo holds its ramp at
// 0), and it turns the forces on again (dhdEnableForce) only once the servo's force is an exact
// zero made after it read that: the first force the double received with forces on again is
// an exact zero, then the servo's push is back.
TEST_F(ForceDimension, AFirmwareWatchdogTripIsReadAndTheForceComesBackFromZero) {
  servo::ForceDimensionDevice d(0, 2000);
  d.open();
  d.enable_force(true, kTestStallS);
  FdServo servo{d, {0.5, 0, 0}};  // isotouch x is FD y
  const auto pushing = [&] {
    const Rows rows = ctl.received();
    return !rows.empty() && rows.back()[2] == 0.5 && (int(rows.back()[4]) & 1);
  };
  ASSERT_TRUE(wait_for(pushing));
  const long enables = ctl.enables(), trips = ctl.watchdog_trips();
  ctl.clear_log();
  // Armed only around the starvation: a loaded machine's device thread late by 10 ms would
  // trip it too.
  ctl.arm_watchdog(1);
  ctl.starve(25);
  ASSERT_TRUE(wait_for([&] { return ctl.watchdog_trips() == trips + 1; })) << "the double's watchdog did not trip";
  ctl.arm_watchdog(0);
  EXPECT_TRUE(wait_for([&] { return d.watchdog_trips() == 1; })) << "the trip was not read from dhdGetStatus";
  EXPECT_TRUE(wait_for([&] { return ctl.enables() == enables + 1 && pushing(); })) << "forces not on again";
  servo.end();
  EXPECT_GT(servo.tripped.load(), 0) << "no reading said the watchdog tripped";
  EXPECT_EQ(d.firmware_force_offs(), 1);
  EXPECT_NE(d.last_error().find("watchdog turned the forces off"), std::string::npos) << d.last_error();
  const Rows rows = ctl.received();
  const std::size_t back = first_on_after_off(rows);
  ASSERT_LT(back, rows.size()) << "no force received with forces on again";
  EXPECT_EQ(rows[back][2], 0.0) << "the force stepped back in at " << rows[back][0] << " s";
  EXPECT_EQ(ctl.watchdog_trips(), trips + 1);
  d.close();
}

// The user turns the forces off with the device's force button (DHD_FORCEOFF_BUTTON): the
// device thread does not turn them on by itself; once the user does, the servo's force comes
// back from an exact zero.
TEST_F(ForceDimension, ForcesTurnedOffAtTheDeviceStayOffUntilTheUserTurnsThemOn) {
  servo::ForceDimensionDevice d(0, 2000);
  d.open();
  d.enable_force(true, kTestStallS);
  FdServo servo{d, {0.5, 0, 0}};
  const auto pushing = [&] {
    const Rows rows = ctl.received();
    return !rows.empty() && rows.back()[2] == 0.5 && (int(rows.back()[4]) & 1);
  };
  ASSERT_TRUE(wait_for(pushing));
  const long enables = ctl.enables();
  ctl.force_button(0);
  EXPECT_TRUE(wait_for([&] { return d.firmware_force_offs() == 1 && d.latest().force_off; }));
  sleep_ms(30);
  EXPECT_EQ(ctl.enables(), enables) << "forces turned on again by isotouch, not by the user";
  EXPECT_EQ(ctl.force_on(), 0);
  EXPECT_EQ(d.watchdog_trips(), 0);
  ctl.clear_log();
  ctl.force_button(1);
  EXPECT_TRUE(wait_for(pushing)) << "the force did not come back";
  servo.end();
  const Rows rows = ctl.received();
  ASSERT_FALSE(rows.empty());
  std::size_t first = 0;
  while (first < rows.size() && !(int(rows[first][4]) & 1)) ++first;
  ASSERT_LT(first, rows.size());
  EXPECT_EQ(rows[first][2], 0.0) << "the force stepped back in when the user turned the forces on";
  d.close();
}
