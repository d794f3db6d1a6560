// The same faults through every backend with a force path of its own, judged on what the
// device, its library or the peer RECEIVED: the v1 emulator (a report device over a socket),
// the OpenHaptics and Force Dimension test doubles (vendor SDKs, loaded as the real ones
// are), and an OpenIGTLink peer on loopback (PLUS's side of `--haptic igtl:`). The servo runs
// at 1 kHz with the scene-like limits (3.3 N, a rate limit of 100 N/s so that a rise takes
// ten ticks) and pushes 1 N; at 0.3 s the fault: a 60 ms renderer stall, 30 ticks of NaN, a
// step (100 ms of zero, then 1 N), the device gone for 100 ms and back, or a 40 ms gap in the
// device's reports. Every received force is finite and within the limit; then per fault:
//   stall      nothing but exact zeros from 3 servo periods after the stall began (a pose
//              stream's period more for the link, which answers poses), then the ramp
//   NaN        exact zeros while the renderer answers NaN, never anything non-finite
//   step       the rise from zero within the rate limit, frame to frame, and no faster
//   reconnect  nothing but zeros while gone, back through the ramp
//   pose gap   zeros during the gap, back through the ramp
// A combination a backend cannot have (an SDK's device thread has no report gap; the link
// does not reconnect: the device reads disconnected and the run ends) is skipped, saying so.
#include <gtest/gtest.h>
#include <dlfcn.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/service/igtl_device.h"
#include "isotouch/service/igtl_message.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/forcedimension_device.h"
#include "isotouch/servo/openhaptics_device.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/socket_link.h"
#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/device_emulator.h"

using namespace isotouch;
using core::Vec3;

namespace {
std::int64_t mono_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

enum class Fault { kStall, kNaN, kStep, kReconnect, kPoseGap };
const char* fault_name(Fault f) {
  switch (f) {
    case Fault::kStall: return "Stall";
    case Fault::kNaN: return "NaN";
    case Fault::kStep: return "Step";
    case Fault::kReconnect: return "Reconnect";
    case Fault::kPoseGap: return "PoseGap";
  }
  return "?";
}

constexpr double kPushN = 1.0, kLimitN = 3.3, kRateNPerS = 100, kPeriodS = 1e-3;
// SCHED_FIFO for the servo, the devices' threads and the peer where allowed (root): the test
// times in servo periods, and a loaded machine's scheduler is not the code under test.
const bool kFifo = geteuid() == 0;
constexpr long kFaultTick = 300;

/// Pushes 1 N up the device's z; from tick kFaultTick the renderer's fault, if any, whose
/// window [from, to] it records [ns, CLOCK_MONOTONIC]: the stall's sleep, the NaN ticks, the
/// step's zero ticks.
class FaultyPush final : public servo::Renderer {
 public:
  explicit FaultyPush(Fault f) : fault_(f) {}
  const char* name() const override { return "faulty push"; }
  void reset() override {}
  std::atomic<std::int64_t> from_ns{0}, to_ns{0};
  servo::HriTick tick(const core::FieldView&, const Vec3&, double) override {
    const long k = ++ticks_;
    servo::HriTick t;
    t.force_n = {0, 0, kPushN};
    if (k < kFaultTick) return t;
    if (k == kFaultTick) from_ns = mono_ns();
    if (fault_ == Fault::kStall && k == kFaultTick) {
      std::this_thread::sleep_for(std::chrono::milliseconds(60));
      to_ns = mono_ns();
    }
    const bool nan = fault_ == Fault::kNaN && k < kFaultTick + 30;
    const bool released = fault_ == Fault::kStep && k < kFaultTick + 100;
    if (nan) t.force_n = {NAN, 0, NAN};
    if (released) t.force_n = {};
    if (!nan && !released && to_ns.load() == 0 && fault_ != Fault::kStall) to_ns = mono_ns();
    return t;
  }

 private:
  Fault fault_;
  long ticks_ = 0;
};

/// One force the device (its library, the peer) received: when it arrived [ns,
/// CLOCK_MONOTONIC] and |F|.
struct Received {
  std::int64_t t_ns;
  double f;
  bool finite;
};

/// A backend: opened, driven by the servo for the scenario, then closed; what it received.
class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string why_not(Fault) const { return ""; }  ///< "" when the fault applies
  virtual void open(Fault f) = 0;
  virtual servo::HapticDeviceIO& io() = 0;
  /// On the test thread while the servo runs, `since_start_s` after it started.
  virtual void act(Fault, double since_start_s) { (void)since_start_s; }
  /// The device-side fault's window (reconnect, pose gap) [ns, CLOCK_MONOTONIC]; 0: none.
  std::int64_t outage_from_ns = 0, outage_to_ns = 0;
  /// Whether rows arrive during an outage (a link that is down receives nothing).
  virtual bool rows_while_down() const { return true; }
  /// A link that sends only in answer to poses (and one zero when they stop).
  virtual bool answers_poses() const { return false; }
  virtual void close() = 0;
  virtual std::vector<Received> received() = 0;
  /// Servo periods of slack for the stall's zero beyond 3 (a link answers poses, 1 ms apart).
  virtual double stall_slack_periods() const { return 0; }
};

// ---- the v1 emulator over its socket ----
class EmuBackend final : public Backend {
 public:
  void open(Fault f) override {
    sim::EmuConfig c;
    c.socket_path = "/tmp/isotouch-test-faults-" + std::to_string(::getpid()) + ".sock";
    c.rate_hz = 1000;
    c.seconds = 0;  // until close() stops it (a slow start must not end it early)
    c.hold_m = Vec3{0, 0, 0};
    c.caps.name = "test-emu";
    c.caps.max_force_n = 10;
    c.caps.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
    c.caps.workspace_max_m = Vec3{0.1, 0.1, 0.1};
    c.caps.watchdog_s = 0.05;
    c.faults.from_first_connection = true;
    c.fifo_priority = kFifo ? 75 : 0;  // firmware-like timing where allowed (as the emulator tests run it)
    if (f == Fault::kReconnect) c.faults.disconnect_at_s = 0.4, c.faults.reconnect_after_s = 0.1;
    if (f == Fault::kPoseGap) c.faults.freeze_at_s = 0.4, c.faults.freeze_for_s = 0.04;
    emu_ = std::make_unique<sim::DeviceEmulator>(c);
    emu_->listen();
    thread_ = std::thread([this] { emu_->run(); });
    dev_ = std::make_unique<servo::ReportDevice>(std::make_unique<servo::SocketLink>(c.socket_path),
                                                 std::make_unique<servo::V1Protocol>(),
                                                 servo::ReportDeviceOptions{.fifo_priority = kFifo ? 70 : 0});
    dev_->open();
    // The emulator's fault times count from the host's connection, made just before this:
    // its window starts no later than 0.4 s from here, and ends no earlier than 10 ms before
    // the end counted from here (the handshake takes a few ms at most).
    const std::int64_t connected = mono_ns();
    if (f == Fault::kReconnect) outage_from_ns = connected + 400'000'000, outage_to_ns = connected + 490'000'000;
    if (f == Fault::kPoseGap) outage_from_ns = connected + 400'000'000, outage_to_ns = connected + 430'000'000;
  }
  bool rows_while_down() const override { return false; }
  servo::HapticDeviceIO& io() override { return *dev_; }
  void close() override {
    if (dev_) dev_->close();
    if (emu_) emu_->stop();
    if (thread_.joinable()) thread_.join();
  }
  std::vector<Received> received() override {
    std::vector<Received> r;
    for (const sim::ReceivedOutput& o : emu_->output_log())
      r.push_back({o.t_ns, o.enable ? core::norm(o.force_n) : 0.0, std::isfinite(core::norm(o.force_n))});
    return r;
  }
  ~EmuBackend() override { close(); }

 private:
  std::unique_ptr<sim::DeviceEmulator> emu_;
  std::unique_ptr<servo::ReportDevice> dev_;
  std::thread thread_;
};

// ---- the vendor SDKs' test doubles (tests/sdk_doubles) ----
class SdkBackend final : public Backend {
 public:
  explicit SdkBackend(bool hd) : hd_(hd) {}
  std::string why_not(Fault f) const override {
    return f == Fault::kPoseGap ? "an SDK's device thread publishes a pose every frame: no report gap" : "";
  }
  void open(Fault) override {
    setenv("ISOTOUCH_HD_LIBRARY", HD_DOUBLE, 1);
    setenv("ISOTOUCH_DHD_LIBRARY", DHD_DOUBLE, 1);
    if (hd_) {
      auto d = std::make_unique<servo::OpenHapticsDevice>();
      d->open();
      dev_ = std::move(d);
    } else {
      auto d = std::make_unique<servo::ForceDimensionDevice>(0, 1000);
      d->open();
      dev_ = std::move(d);
    }
    void* h = dlopen(hd_ ? HD_DOUBLE : DHD_DOUBLE, RTLD_NOW | RTLD_GLOBAL);
    log_ = reinterpret_cast<int (*)(double*, int)>(dlsym(h, hd_ ? "hdDoubleLog" : "dhdDoubleLog"));
    clear_ = reinterpret_cast<void (*)()>(dlsym(h, hd_ ? "hdDoubleClearLog" : "dhdDoubleClearLog"));
    vanish_ = reinterpret_cast<void (*)(int)>(dlsym(h, hd_ ? "hdDoubleVanish" : "dhdDoubleVanish"));
    start_s_ = reinterpret_cast<double (*)()>(dlsym(h, hd_ ? "hdDoubleStartS" : "dhdDoubleStartS"));
    clear_();
  }
  servo::HapticDeviceIO& io() override { return *dev_; }
  void act(Fault f, double since_start_s) override {
    if (f != Fault::kReconnect) return;
    if (since_start_s >= 0.4 && !gone_ && !back_) vanish_(1), gone_ = true, outage_from_ns = mono_ns();
    if (since_start_s >= 0.5 && gone_) outage_to_ns = mono_ns(), vanish_(0), gone_ = false, back_ = true;
  }
  void close() override {
    if (dev_) dev_->close();
  }
  std::vector<Received> received() override {
    std::vector<std::array<double, 5>> rows(1 << 16);
    const int n = log_(rows.front().data(), int(rows.size()));
    rows.resize(std::size_t(std::clamp(n, 0, int(rows.size()))));
    std::vector<Received> r;
    const double t0 = start_s_();  // the log's times are since this [s, mono]
    for (const auto& row : rows) {
      const double f = std::sqrt(row[1] * row[1] + row[2] * row[2] + row[3] * row[3]);
      // What reached the motors: the force while output was on and the device present.
      const bool applied = (int(row[4]) & 1) && !(int(row[4]) & 2);
      r.push_back({std::int64_t((t0 + row[0]) * 1e9), applied ? f : 0.0, std::isfinite(f)});
    }
    return r;
  }

 private:
  bool hd_;
  std::unique_ptr<servo::SdkDevice> dev_;
  int (*log_)(double*, int) = nullptr;
  void (*clear_)() = nullptr;
  void (*vanish_)(int) = nullptr;
  double (*start_s_)() = nullptr;
  bool gone_ = false, back_ = false;
};

// ---- an OpenIGTLink peer on loopback (PLUS's side) ----
class IgtlBackend final : public Backend {
 public:
  std::string why_not(Fault f) const override {
    return f == Fault::kReconnect ? "the link does not reconnect: the device reads disconnected and the run ends" : "";
  }
  double stall_slack_periods() const override { return 1; }
  bool answers_poses() const override { return true; }
  void open(Fault) override {
    listener_ = std::make_unique<service::Listener>("127.0.0.1", 0);
    peer_ = std::thread([this] { serve(); });
    service::IgtlDeviceOptions o;
    o.host = "127.0.0.1";
    o.port = listener_->port();
    o.measure_s = 0.3;
    o.fifo_priority = kFifo ? 70 : 0;  // as `--haptic igtl:` runs it where allowed
    dev_ = std::make_unique<service::IgtlDevice>(o);
  }
  servo::HapticDeviceIO& io() override { return *dev_; }
  void act(Fault f, double since_start_s) override {
    if (f != Fault::kPoseGap) return;
    const bool pause = since_start_s >= 0.4 && since_start_s < 0.44;
    if (pause && !pause_.load()) outage_from_ns = mono_ns();
    if (!pause && pause_.load()) outage_to_ns = mono_ns();
    pause_.store(pause);
  }
  void close() override {
    dev_.reset();  // its last act: a zero
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    stop_ = true;
    if (peer_.joinable()) peer_.join();
  }
  std::vector<Received> received() override {
    std::lock_guard<std::mutex> lock(mu_);
    return got_;
  }
  ~IgtlBackend() override { close(); }

 private:
  void serve() {
    // The peer's threads at a device loop's priority where allowed (PLUS's is): what they
    // time is the link's, not this machine's other load.
    if (kFifo) servo::make_thread_realtime("test peer", true, 60, false, -1);
    int fd = -1;
    while (fd < 0 && !stop_) fd = listener_->accept(50);
    if (fd < 0) return;
    service::Connection conn(fd, 2000, 2000, &stop_);
    std::thread reader([&] {
      if (kFifo) servo::make_thread_realtime("test peer reader", true, 60, false, -1);
      for (;;) {
        const service::Incoming in = service::read_message(conn, service::MessageLimits{});
        if (in.kind == service::Incoming::Kind::kClosed || in.kind == service::Incoming::Kind::kBroken) break;
        if (in.kind != service::Incoming::Kind::kTransform || in.device != "Force") continue;
        const double f = std::sqrt(in.matrix[0][3] * in.matrix[0][3] + in.matrix[1][3] * in.matrix[1][3] +
                                   in.matrix[2][3] * in.matrix[2][3]);
        std::lock_guard<std::mutex> lock(mu_);
        got_.push_back({mono_ns(), f, std::isfinite(f)});
      }
    });
    const double pose[3] = {0, 0, 0};
    for (auto next = std::chrono::steady_clock::now(); !stop_;) {
      std::this_thread::sleep_until(next);
      if (!pause_.load()) conn.send(service::pack_translation("StylusToTracker", pose));
      next = std::max(next + std::chrono::milliseconds(1), std::chrono::steady_clock::now());
    }
    conn.shutdown();
    reader.join();
  }
  std::unique_ptr<service::Listener> listener_;
  std::unique_ptr<service::IgtlDevice> dev_;
  std::thread peer_;
  std::atomic<bool> stop_{false}, pause_{false};
  std::mutex mu_;
  std::vector<Received> got_;
};

std::unique_ptr<Backend> make_backend(const std::string& name) {
  if (name == "Emulator") return std::make_unique<EmuBackend>();
  if (name == "OpenHaptics") return std::make_unique<SdkBackend>(true);
  if (name == "ForceDimension") return std::make_unique<SdkBackend>(false);
  return std::make_unique<IgtlBackend>();
}

/// Runs the scenario on `b`: the servo at 1 kHz for 0.8 s rendering `push`; returns what was
/// received.
std::vector<Received> run_scenario(Backend& b, Fault fault, FaultyPush& push) {
  b.open(fault);
  servo::TripleBuffer<core::SampleField> published;
  published.publish(std::make_shared<const core::SampleField>(sim::plane_field({0, 0, 1}, {0.016, 0.016, 0.016})));
  servo::ServoThreadConfig sc;
  sc.rate_hz = 1.0 / kPeriodS;
  sc.force_limit_n = kLimitN;
  sc.max_force_rate_n_per_s = kRateNPerS;
  sc.sched_fifo = kFifo;
  sc.pin_cpu = sc.lock_memory = false;
  {
    servo::ServoThread servo(published, push, b.io(), sc);
    servo.start();
    const std::int64_t t0 = mono_ns();
    // 0.8 s, and on a slow machine on until the renderer's fault is 0.3 s past (its ticks
    // count only while the device is ok), 5 s at most.
    const auto more = [&] {
      const std::int64_t now = mono_ns(), to = push.to_ns.load();
      const bool renderer_fault = fault == Fault::kStall || fault == Fault::kNaN || fault == Fault::kStep;
      return now - t0 < 800'000'000 || (renderer_fault && (to == 0 || now - to < 300'000'000));
    };
    while (more() && mono_ns() - t0 < 5'000'000'000) {
      b.act(fault, double(mono_ns() - t0) * 1e-9);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    servo.stop();
  }
  b.close();
  return b.received();
}

using Param = std::tuple<std::string, Fault>;
class BackendFaults : public ::testing::TestWithParam<Param> {};

TEST_P(BackendFaults, WhatTheDeviceReceivedKeepsTheRules) {
#if defined(__SANITIZE_THREAD__)
  // Judged in servo periods: under ThreadSanitizer's slowdown the periods are not the code's.
  // (The same threads run under it in test_sdk_devices, test_igtl_device, test_device_emu.)
  GTEST_SKIP() << "timed in servo periods: not under ThreadSanitizer";
#endif
  const auto& [name, fault] = GetParam();
  std::unique_ptr<Backend> b = make_backend(name);
  if (const std::string why = b->why_not(fault); !why.empty()) GTEST_SKIP() << name << ": " << why;
  FaultyPush push(fault);
  const std::vector<Received> r = run_scenario(*b, fault, push);
  ASSERT_GT(r.size(), 100u) << "the device received too little";
  // Always: finite, within the push (and so the limit).
  for (std::size_t i = 0; i < r.size(); ++i) {
    ASSERT_TRUE(r[i].finite) << "row " << i << ": a non-finite force reached the device";
    ASSERT_LE(r[i].f, kPushN + 1e-9) << "row " << i;
  }
  // The fault's window: the renderer's (stall, NaN, step) or the device's (reconnect, gap).
  const bool device_side = fault == Fault::kReconnect || fault == Fault::kPoseGap;
  const std::int64_t from = device_side ? b->outage_from_ns : push.from_ns.load();
  const std::int64_t to = device_side ? b->outage_to_ns : push.to_ns.load();
  ASSERT_TRUE(from > 0 && to > from) << "the fault never happened";
  // Inside it, after 3 servo periods (the link's slack more, 1 ms for the device's own thread
  // to run): nothing but exact zeros. The step's window starts with a rate-limited release.
  const double settle_s = fault == Fault::kStep ? kPushN / kRateNPerS : 0.0;
  const auto zero_from = from + std::int64_t(((3 + b->stall_slack_periods()) * kPeriodS + 1e-3 + settle_s) * 1e9);
  long zeros = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    if (r[i].t_ns <= zero_from || r[i].t_ns >= to) continue;
    EXPECT_EQ(r[i].f, 0.0) << "row " << i << ", " << double(r[i].t_ns - from) * 1e-6 << " ms into the fault";
    ++zeros;
  }
  // A device that keeps receiving got zeros in there; a link that answers poses got one zero
  // when the stream went stale (maybe before `zero_from`), and it is what the peer holds.
  std::size_t last_in = r.size();
  for (std::size_t i = 0; i < r.size(); ++i)
    if (r[i].t_ns > from && r[i].t_ns < to) last_in = i;
  if (b->answers_poses() && fault == Fault::kPoseGap) {
    ASSERT_LT(last_in, r.size()) << "no zero when the stream stopped";
    EXPECT_EQ(r[last_in].f, 0.0) << "the peer holds a force through the gap";
  } else if (b->rows_while_down() || fault != Fault::kReconnect) {
    EXPECT_GE(zeros, 1) << "no row inside the fault";
  }
  // After it: the first force, from zero - through the servo's ramp where the device was lost
  // or stalled (0.02 N on its first tick), at the gate's rate after NaN or the step.
  std::size_t back = 0;
  while (back < r.size() && !(r[back].t_ns > to && r[back].f > 0)) ++back;
  ASSERT_LT(back, r.size()) << "the force never came back";
  ASSERT_GT(back, 0u);
  // Bounded by the time since the row before it (a writer that sent late sent more), plus a
  // servo period: at the gate's rate after NaN or the step, at the ramp's (1 N over 50 ms)
  // after a stall or an outage.
  const double since_s = double(r[back].t_ns - r[back - 1].t_ns) * 1e-9 + kPeriodS;
  const bool ramped = fault != Fault::kNaN && fault != Fault::kStep;
  const double bound = ramped ? kPushN * since_s / 0.05 : kRateNPerS * since_s;
  EXPECT_LE(r[back].f, bound + 2e-3) << "the force came back " << (ramped ? "with a jump, not the ramp" : "faster than the rate")
                                     << " (" << since_s * 1e3 << " ms after the row before)";
  // The rise to the full push: row to row within the rate over the rows' distance (two servo
  // periods more: a late tick's write and the next on-time one may fall between two frames;
  // each write changes the force by at most the rate over a period), and no faster overall.
  std::size_t full = back;
  while (full < r.size() && r[full].f < kPushN - 2e-3) ++full;
  ASSERT_LT(full, r.size()) << "the push never came back";
  for (std::size_t i = back + 1; i <= full; ++i) {
    const double dt = double(r[i].t_ns - r[i - 1].t_ns) * 1e-9;
    EXPECT_LE(r[i].f - r[i - 1].f, kRateNPerS * (dt + 2 * kPeriodS) + 2e-3) << "row " << i << " of the rise";
  }
  EXPECT_GE(double(r[full].t_ns - r[back - 1].t_ns) * 1e-9, (kPushN - 2e-3) / kRateNPerS - 2 * kPeriodS)
      << "the rise from zero was faster than the rate limit";
  if (std::getenv("BACKEND_FAULTS_DEBUG"))
    for (const Received& x : r)
      if (x.t_ns > from - 5'000'000 && x.t_ns < to + 30'000'000)
        std::printf("  %+8.3f ms  %.4f\n", double(x.t_ns - from) * 1e-6, x.f);
  std::printf("%s / %s: %zu rows received, %ld zeros in the fault's %.1f ms, back at %.3f N, full %.1f ms later\n",
              name.c_str(), fault_name(fault), r.size(), zeros, double(to - from) * 1e-6, r[back].f,
              double(r[full].t_ns - r[back].t_ns) * 1e-6);
}

INSTANTIATE_TEST_SUITE_P(
    EveryBackend, BackendFaults,
    ::testing::Combine(::testing::Values("Emulator", "OpenHaptics", "ForceDimension", "Igtl"),
                       ::testing::Values(Fault::kStall, Fault::kNaN, Fault::kStep, Fault::kReconnect, Fault::kPoseGap)),
    [](const ::testing::TestParamInfo<Param>& p) {
      return std::get<0>(p.param) + "_" + fault_name(std::get<1>(p.param));
    });

}  // namespace
