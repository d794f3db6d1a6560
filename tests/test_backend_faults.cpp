// The same faults through every backend with a force path of its own, judged on what the
// device, its library or the peer RECEIVED: the v1 emulator and the Polhem emulator (report
// devices over a socket: the Polhem's currents turned back into the force they make), the
// OpenHaptics and Force Dimension test doubles (vendor SDKs, loaded as the real ones are), an
// OpenIGTLink peer on loopback (PLUS's side of `--haptic igtl:`), and a client of serve's
// TRANSFORM stream (`serve --reply-force`: the TransformDevice and its reply thread). The servo runs
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
// A combination a backend cannot have (an SDK's device thread has no report gap; a link does
// not reconnect) is skipped, saying so.
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
#include "isotouch/service/plus_peer.h"
#include "isotouch/service/stream_host.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/forcedimension_device.h"
#include "isotouch/servo/openhaptics_device.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/socket_link.h"
#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/device_emulator.h"
#include "isotouch/tests/sched_canary.h"

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
  /// When the last tick before the fault returned its force: the servo's last write to the
  /// device comes after it, so a bound timed from here is never looser than one timed from
  /// that write.
  std::atomic<std::int64_t> last_push_ns{0};
  servo::HriTick tick(const core::FieldView&, const Vec3&, double) override {
    const long k = ++ticks_;
    servo::HriTick t;
    t.force_n = {0, 0, kPushN};
    if (k < kFaultTick) {
      last_push_ns = mono_ns();
      return t;
    }
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
  /// What the front end sets for this device (serve's stream: its stale timeout).
  virtual void configure(servo::ServoThreadConfig&) const {}
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
  /// Servo periods of slack beyond 3 for the zeros of a fault other than a stall (a link
  /// answers poses, 1 ms apart).
  virtual double stall_slack_periods() const { return 0; }
  /// The servo's stale timeout with this device [s] (set when the scenario runs).
  double stale_s = 0;
  double own_rate_hz = 0;  ///< the rate of the loop the device applies forces in (0: none of its own)
  /// How far the force received may lie from the force sent [N].
  virtual double tolerance_n() const { return 1e-9; }
};

// ---- the emulator over its socket: protocol v1, or the Polhem's reports ----
class EmuBackend final : public Backend {
 public:
  explicit EmuBackend(bool polhem) : polhem_(polhem) {}
  std::string why_not(Fault f) const override {
    // The host cannot tell a link that came back from a unit that was power-cycled (its
    // counts then uncalibrated, info 0 all the same): a reconnected Polhem gets no current
    // until it is calibrated again (the user presses the handle into its switch), tested in
    // test_device_emu; so no force comes back within this scenario.
    return polhem_ && f == Fault::kReconnect ? "a reconnected Polhem gets no current until it is calibrated again" : "";
  }
  void open(Fault f) override {
    sim::EmuConfig c;
    c.polhem = polhem_;
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
    std::unique_ptr<servo::DeviceProtocol> protocol;
    if (polhem_) protocol = std::make_unique<servo::PolhemProtocol>(c.polhem_config);
    else protocol = std::make_unique<servo::V1Protocol>();
    dev_ = std::make_unique<servo::ReportDevice>(std::make_unique<servo::SocketLink>(c.socket_path), std::move(protocol),
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
  // The Polhem receives motor currents, not a force: the force they make at the hand's pose
  // differs from the one asked at the encoders' pose by the encoders' quantization and the
  // Jacobian's central differences (up to 0.18 % seen): 0.5 % of the push.
  double tolerance_n() const override { return polhem_ ? 0.005 * kPushN : 1e-9; }
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
  bool polhem_;
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

/// What a PLUS-like peer received: |F| of each Force.
std::vector<Received> peer_received(const service::PlusPeer& peer) {
  std::vector<Received> r;
  for (const service::PeerForce& f : peer.forces()) r.push_back({f.t_ns, core::norm(f.f), std::isfinite(core::norm(f.f))});
  return r;
}

/// The pose gap's window on the peer's side: from 0.4 s to 0.44 s it sends no pose.
void pause_poses(service::PlusPeer& peer, double since_start_s, Backend& b) {
  const bool pause = since_start_s >= 0.4 && since_start_s < 0.44;
  if (pause && b.outage_from_ns == 0) b.outage_from_ns = mono_ns();
  if (!pause && b.outage_from_ns != 0 && b.outage_to_ns == 0) b.outage_to_ns = mono_ns();
  peer.pause(pause);
}

// ---- an OpenIGTLink peer on loopback (PLUS's side of `--haptic igtl:`) ----
class IgtlBackend final : public Backend {
 public:
  std::string why_not(Fault f) const override {
    return f == Fault::kReconnect ? "the link does not reconnect: the device reads disconnected and the run ends" : "";
  }
  double stall_slack_periods() const override { return 1; }
  bool answers_poses() const override { return true; }
  void open(Fault) override {
    service::PlusPeerOptions po;
    po.fifo_priority = kFifo ? 60 : 0;  // PLUS's device loop's priority where allowed
    peer_ = std::make_unique<service::PlusPeer>(po);
    service::IgtlDeviceOptions o;
    o.host = "127.0.0.1";
    o.port = peer_->port();
    o.measure_s = 0.3;
    o.fifo_priority = kFifo ? 70 : 0;  // as `--haptic igtl:` runs it where allowed
    dev_ = std::make_unique<service::IgtlDevice>(o);
  }
  servo::HapticDeviceIO& io() override { return *dev_; }
  void act(Fault f, double since_start_s) override {
    if (f == Fault::kPoseGap) pause_poses(*peer_, since_start_s, *this);
  }
  void close() override {
    dev_.reset();  // its last act: a zero
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (peer_) peer_->finish();
  }
  std::vector<Received> received() override { return peer_received(*peer_); }
  ~IgtlBackend() override { close(); }

 private:
  std::unique_ptr<service::PlusPeer> peer_;
  std::unique_ptr<service::IgtlDevice> dev_;
};

// ---- a client of serve's TRANSFORM stream (`serve --reply-force`) ----
class ServeStreamBackend final : public Backend {
 public:
  std::string why_not(Fault f) const override {
    return f == Fault::kReconnect ? "a client that comes back is a new stream (the pose gap is the servo's side of it)" : "";
  }
  double stall_slack_periods() const override { return 1; }
  bool answers_poses() const override { return true; }
  // Stale after 3 of the stream's periods, as `--haptic igtl:` measures its own.
  void configure(servo::ServoThreadConfig& c) const override { c.stale_timeout_s = 3 * kPeriodS; }
  void open(Fault) override {
    host_ = std::make_unique<service::StreamHost>(service::StreamReplyOptions{kFifo, 3 * kPeriodS});
    service::PlusPeerOptions po;
    po.connect_host = "127.0.0.1";
    po.connect_port = host_->port();
    po.fifo_priority = kFifo ? 60 : 0;
    peer_ = std::make_unique<service::PlusPeer>(po);
  }
  servo::HapticDeviceIO& io() override { return host_->device(); }
  void act(Fault f, double since_start_s) override {
    if (f == Fault::kPoseGap) pause_poses(*peer_, since_start_s, *this);
  }
  void close() override {
    if (host_) host_->stop();  // the replies' last act: a zero
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (peer_) peer_->finish();
  }
  std::vector<Received> received() override { return peer_received(*peer_); }
  ~ServeStreamBackend() override { close(); }

 private:
  std::unique_ptr<service::StreamHost> host_;
  std::unique_ptr<service::PlusPeer> peer_;
};

std::unique_ptr<Backend> make_backend(const std::string& name) {
  if (name == "Emulator") return std::make_unique<EmuBackend>(false);
  if (name == "Polhem") return std::make_unique<EmuBackend>(true);
  if (name == "ServeStream") return std::make_unique<ServeStreamBackend>();
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
  b.configure(sc);
  // As ServoThread judges it: the front end's, else the device's own, else two periods.
  const double device_stale_s = b.io().caps().stale_timeout_s;
  b.own_rate_hz = b.io().caps().output_rate_hz;
  b.stale_s = sc.stale_timeout_s > 0 ? sc.stale_timeout_s : device_stale_s > 0 ? device_stale_s : 2 * kPeriodS;
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
  isotouch::test::SchedCanary canary;  // how long the machine was gone: widens the fault's timed bounds by that alone
  const std::vector<Received> r = run_scenario(*b, fault, push);
  canary.stop();
  ASSERT_GT(r.size(), 100u) << "the device received too little";
  const double tol = std::max(2e-3, 2 * b->tolerance_n());  // for the ramp's and the rise's steps
  // Always: finite, within the push (and so the limit).
  for (std::size_t i = 0; i < r.size(); ++i) {
    ASSERT_TRUE(r[i].finite) << "row " << i << ": a non-finite force reached the device";
    ASSERT_LE(r[i].f, kPushN + b->tolerance_n()) << "row " << i;
  }
  // The fault's window: the renderer's (stall, NaN, step) or the device's (reconnect, gap).
  const bool device_side = fault == Fault::kReconnect || fault == Fault::kPoseGap;
  const std::int64_t from = device_side ? b->outage_from_ns : push.from_ns.load();
  const std::int64_t to = device_side ? b->outage_to_ns : push.to_ns.load();
  ASSERT_TRUE(from > 0 && to > from) << "the fault never happened";
  // Inside it, after 3 servo periods (and the time the canaries saw the machine gone until
  // the row): nothing but exact zeros. A stall is timed from the servo's last write before
  // it, on every backend and link alike (the zero arrives in time); the other faults from
  // their start, with the link's slack and 1 ms more for the device's own thread to run. A gap in the device's reports is judged stale after the
  // servo's stale timeout with the device, and a tick later written as zero. The step's
  // window starts with a rate-limited release.
  const double settle_s = fault == Fault::kStep ? kPushN / kRateNPerS : 0.0;
  const double off_s = fault == Fault::kPoseGap ? b->stale_s + kPeriodS : 3 * kPeriodS;
  // A stall is timed from the servo's last write before it (the rule's promise: a disabled
  // zero within 3 periods of it), the other renderer faults from their first faulty tick.
  const std::int64_t judged_from = fault == Fault::kStall ? push.last_push_ns.load() : from;
  // A device that applies forces in its own loop (OpenHaptics, Force Dimension) looks for the
  // stall at its own ticks, half a device period early (servo/stall_rule.cpp): at worst half a
  // device period past 2.5 servo periods, then its frame's reads before the zero is set.
  // A link's peer receives the zero over loopback TCP and wakes its reader for it: 0.5 ms
  // for that transport (the canaries see lost CPU, not a socket's or a wake-up's latency).
  const double own_hz = b->own_rate_hz;
  const double stall_slack_s = (own_hz > 0 ? 0.5 / own_hz : 0.0) + (b->answers_poses() ? 0.5e-3 : 0.0);
  const std::int64_t slack_ns = fault == Fault::kStall
                                    ? std::int64_t(stall_slack_s * 1e9)
                                    : std::int64_t(b->stall_slack_periods() * kPeriodS * 1e9) + 1'000'000;
  const auto zero_from = judged_from + std::int64_t((off_s + settle_s) * 1e9) + slack_ns;
  if (fault == Fault::kStall) {  // the zero itself arrived in time, not only no force after it
    std::size_t z = 0;
    while (z < r.size() && !(r[z].t_ns > from && r[z].f == 0.0)) ++z;
    ASSERT_LT(z, r.size()) << "no zero during the stall";
    const double ms = double(r[z].t_ns - judged_from) * 1e-6;
    std::printf("%s / Stall: the first zero arrived %.3f ms after the last write (%s)\n", name.c_str(), ms,
                canary.describe(judged_from, r[z].t_ns).c_str());
    EXPECT_LE(r[z].t_ns, zero_from + canary.lost_ns(judged_from, r[z].t_ns))
        << "the zero arrived " << ms << " ms after the last write, past 3 periods; "
        << canary.describe(judged_from, r[z].t_ns);
  }
  long zeros = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    if (r[i].t_ns <= zero_from + canary.lost_ns(judged_from, r[i].t_ns) || r[i].t_ns >= to) continue;
    EXPECT_EQ(r[i].f, 0.0) << "row " << i << ", " << double(r[i].t_ns - judged_from) * 1e-6
                           << " ms after the fault's judged start; " << canary.describe(judged_from, r[i].t_ns);
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
    // Rows to judge are owed only where the machine ran for a few periods of the judged
    // window: the canaries' lost time shortens it as it delays each row.
    const std::int64_t left_ns = to - zero_from - canary.lost_ns(judged_from, to);
    if (left_ns > std::int64_t(3 * kPeriodS * 1e9)) {
      EXPECT_GE(zeros, 1) << "no row inside the fault; " << canary.describe(from, to);
    } else {
      std::printf("%s / %s: the machine was gone for all but %.1f ms of the judged window: no row owed (%s)\n",
                  name.c_str(), fault_name(fault), double(left_ns) * 1e-6, canary.describe(from, to).c_str());
    }
  }
  // After it: the first force, from zero.
  std::size_t back = 0;
  while (back < r.size() && !(r[back].t_ns > to && r[back].f > 0)) ++back;
  ASSERT_LT(back, r.size()) << "the force never came back";
  ASSERT_GT(back, 0u);
  // From the fault's end on, every force up to the full push lies under an envelope that
  // starts from zero at the fault's end: the ramp's (1 N over 50 ms) after a stall or an
  // outage, the gate's rate after NaN or the step; two servo periods more (a late tick's
  // write and the next on-time one). Judged against the end of the fault, not the row
  // before: a row's time is its arrival, and a receiver that was starved (a busy link reader,
  // a lock-step device) gets the rows before it late, never the row itself early.
  const bool ramped = fault != Fault::kNaN && fault != Fault::kStep;
  const double slope = ramped ? kPushN / 0.05 : kRateNPerS;  // [N/s]
  std::size_t full = back;
  while (full < r.size() && r[full].f < kPushN - tol) ++full;
  ASSERT_LT(full, r.size()) << "the push never came back";
  for (std::size_t i = back; i <= full; ++i) {
    const double since_s = double(r[i].t_ns - to) * 1e-9;
    EXPECT_LE(r[i].f, slope * (since_s + 2 * kPeriodS) + tol)
        << "row " << i - back << " of the return, " << since_s * 1e3 << " ms after the fault: "
        << (ramped ? "a jump, not the ramp" : "faster than the rate");
  }
  // And no faster overall than the rate: the full push arrives no earlier than its rise takes.
  EXPECT_GE(double(r[full].t_ns - to) * 1e-9, (kPushN - tol) / kRateNPerS - 2 * kPeriodS)
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
    ::testing::Combine(::testing::Values("Emulator", "Polhem", "OpenHaptics", "ForceDimension", "Igtl", "ServeStream"),
                       ::testing::Values(Fault::kStall, Fault::kNaN, Fault::kStep, Fault::kReconnect, Fault::kPoseGap)),
    [](const ::testing::TestParamInfo<Param>& p) {
      return std::get<0>(p.param) + "_" + fault_name(std::get<1>(p.param));
    });

}  // namespace
