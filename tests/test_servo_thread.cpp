// The real-time servo thread: runs, reads snapshots a publisher swaps at full speed,
// allocates nothing on the servo thread (counted by a replaced operator new), renders real
// contact forces, passes the measured period to the renderer, leaves the device with an
// exact zero force, and stays quiet under ThreadSanitizer (the tsan preset runs this file).
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <thread>

#include "analytic_fields.h"
#include "hri.h"
#include "servo_thread.h"
#include "sim_device_io.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

namespace {
thread_local bool t_is_servo = false;
std::atomic<long> g_servo_allocations{0};
/// Frees on the servo thread while it ticks (a snapshot released there would be one).
std::atomic<long> g_servo_frees{0};

/// A renderer spy: forwards to HRI and keeps the dt of each tick (preallocated).
class DtSpy final : public Renderer {
 public:
  explicit DtSpy(const HriParams& p) : hri_(p) {}
  const char* name() const override { return "spy"; }
  void reset() override { hri_.reset(); }
  HriTick tick(const SampleField& f, const Vec3& hip, double dt_s) override {
    if (n_ < dt_.size()) dt_[n_++] = dt_s;
    return hri_.tick(f, hip, dt_s);
  }
  std::size_t n() const { return n_; }
  double dt(std::size_t i) const { return dt_[i]; }

 private:
  HriRenderer hri_;
  std::array<double, 4096> dt_{};
  std::size_t n_ = 0;
};

/// A device whose HIP comes from 2 mm outside a floor (plane z = 10 mm, inside below) to
/// 1 mm inside it over the first 200 ticks, then stays; keeps every force it is sent.
struct ApproachingProbe final : HapticDeviceIO {
  long writes = 0;
  Vec3 last{1, 1, 1};
  double max_f_outside = 0, max_f_inside = 0;
  long forced_ticks_inside = 0;
  double z() const { return 0.012 - 0.003 * std::min(1.0, double(writes) / 200.0); }
  Vec3 read_position_m() override { return {0.016, 0.016, z()}; }
  void write_force_n(const Vec3& f) override {
    const double m = norm(f);
    if (z() > 0.010) max_f_outside = std::max(max_f_outside, m);
    else {
      max_f_inside = std::max(max_f_inside, m);
      if (m > 0) ++forced_ticks_inside;
    }
    last = f;
    ++writes;
  }
};
}  // namespace

// The replaced operator new / delete pair malloc and free; GCC's -Wmismatched-new-delete
// sees the inlined malloc behind new and warns at every delete in this file.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  if (t_is_servo) g_servo_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept {
  if (t_is_servo && p) g_servo_frees.fetch_add(1, std::memory_order_relaxed);
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept { operator delete(p); }

TEST(ServoThread, RunsWithAPublisherSwappingSnapshotsAndAllocatesNothing) {
  const Vec3 c{0.024, 0.024, 0.024};
  // Two versions of the "edited" volume: the sphere grows and shrinks by 1 mm.
  auto a = std::make_shared<SampleField>(sphere_field(c, 0.015));
  auto b = std::make_shared<SampleField>(sphere_field(c, 0.016));
  TripleBuffer<SampleField> published;
  published.publish(a);

  HriParams hp;
  hp.tau = 0;
  hp.plane_update_period = 5;
  hp.rate_hz = 2000;
  HriRenderer renderer(hp);
  ScriptParams sp;
  sp.ray_origin_frac = {0.5, 0.5, 1.3};
  sp.stroke_length_m = 0.01;
  const TouchScript script = make_touch_script(*a, hp, sp);
  Vec3 p0, v0;
  script.at(0, p0, v0);
  SimDevice dev({}, p0);
  SimDeviceIO io(dev, script, 1.0 / hp.rate_hz);

  // Contact and plane updates counted on the servo thread (atomics: nothing allocated), so
  // the allocation count below is of ticks that rendered contact, not of free motion alone.
  struct ContactCount final : TickObserver {
    std::atomic<long> contact{0}, updates{0};
    void on_tick(const TickRecord& r) noexcept override {
      if (r.out.contact) contact.fetch_add(1, std::memory_order_relaxed);
      if (r.out.plane_update) updates.fetch_add(1, std::memory_order_relaxed);
    }
  } count;
  ServoThreadConfig cfg;
  cfg.rate_hz = hp.rate_hz;
  cfg.record_ticks = 10000;
  cfg.on_thread_start = [] { t_is_servo = true; };
  cfg.observer = &count;
  ServoThread servo(published, renderer, io, cfg);

  std::atomic<bool> stop{false};
  std::atomic<long> publications{0};
  std::thread publisher([&] {
    std::uint64_t v = 1;
    while (!stop.load()) {
      // Copies of prebuilt snapshots: the swap itself is what is exercised.
      auto next = std::make_shared<SampleField>(*((v & 1) ? b : a));
      next->version = ++v;
      published.publish(std::move(next));
      publications.fetch_add(1);
    }
  });
  const std::string note = servo.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  // Read while the servo still ticks: the thread's own exit (std::thread frees its state
  // there) is not the tick's.
  const long allocations = g_servo_allocations.load(), frees = g_servo_frees.load();
  servo.stop();
  stop = true;
  publisher.join();

  EXPECT_GT(servo.ticks(), 500);                   // ran (2 kHz for 1.5 s = 3000 nominal)
  std::printf("servo thread: %ld ticks, %ld in contact, %ld plane updates, %ld allocations\n", servo.ticks(),
              count.contact.load(), count.updates.load(), allocations);
  EXPECT_GT(count.contact.load(), 100);            // pressed the sphere: the contact path ran
  EXPECT_GT(count.updates.load(), 10);
  EXPECT_GT(servo.snapshot_changes(), 10);         // and saw the publisher's snapshots
  EXPECT_GT(publications.load(), 10);
  EXPECT_EQ(servo.faults(), 0);
  EXPECT_EQ(allocations, 0) << "the servo thread allocated";
  EXPECT_EQ(frees, 0) << "the servo thread freed memory (a snapshot released on the servo thread?)";
  EXPECT_EQ(dev.refused_commands(), 0);            // never a NaN force
  EXPECT_FALSE(servo.period_errors_ns().empty());
  // The real-time setup is asked for by default; whatever was refused is said, nothing else.
  EXPECT_EQ(note.find("SCHED_FIFO") != std::string::npos, !servo.got_fifo()) << note;
  EXPECT_EQ(note.find("not pinned") != std::string::npos, servo.pinned_cpu() < 0) << note;
  EXPECT_EQ(note.find("mlockall") != std::string::npos, !servo.memory_locked()) << note;
}

// A rate that gives no period is refused when the thread is made, naming the field.
TEST(ServoThread, ARateWithoutAPeriodIsRefused) {
  TripleBuffer<SampleField> published;
  HriRenderer renderer(HriParams{});
  SimDevice dev({}, Vec3{});
  for (const double rate : {0.0, -1000.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    ServoThreadConfig cfg;
    cfg.rate_hz = rate;
    SimDeviceIO io(dev, TouchScript{}, 1e-3);
    try {
      ServoThread servo(published, renderer, io, cfg);
      ADD_FAILURE() << "rate " << rate << " Hz was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("rate_hz"), std::string::npos) << e.what();
    }
  }
}

TEST(ServoThread, RendersContactFromOutsideAndLeavesExactlyZeroForceOnStop) {
  const SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});  // floor at z = 10 mm
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(f));
  HriParams hp;
  hp.rate_hz = 10000;
  HriRenderer renderer(hp);
  ApproachingProbe probe;
  ServoThreadConfig cfg;
  cfg.rate_hz = hp.rate_hz;
  ServoThread servo(published, renderer, probe, cfg);
  servo.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto t0 = std::chrono::steady_clock::now();
  servo.stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(200));
  // After join the probe is ours to read.
  ASSERT_GT(probe.writes, 300) << "the probe never got 1 mm inside";
  EXPECT_EQ(probe.max_f_outside, 0.0);           // free space: no force
  EXPECT_GT(probe.forced_ticks_inside, 50);      // contact: forces flowed while inside
  // 1 mm in, K = 800 N/m: about 0.8 N (the damping adds while the probe still moves).
  EXPECT_GT(probe.max_f_inside, 0.6);
  EXPECT_LT(probe.max_f_inside, hp.force_limit_n);
  EXPECT_EQ(probe.last.x, 0.0);                  // the last command after stop: exactly zero
  EXPECT_EQ(probe.last.y, 0.0);
  EXPECT_EQ(probe.last.z, 0.0);
}

TEST(ServoThread, PassesTheMeasuredPeriodToTheRenderer) {
  const SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(f));
  HriParams hp;
  hp.rate_hz = 4000;
  DtSpy spy(hp);
  ApproachingProbe probe;
  ServoThreadConfig cfg;
  cfg.rate_hz = hp.rate_hz;
  cfg.record_ticks = 4096;
  ServoThread servo(published, spy, probe, cfg);
  servo.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  servo.stop();
  const auto& err = servo.period_errors_ns();
  ASSERT_GT(spy.n(), 200u);
  EXPECT_EQ(spy.dt(0), 0.0);  // first tick: no measured period yet, the renderer takes 1/rate
  const double T = 1.0 / hp.rate_hz;
  const std::size_t n = std::min(spy.n(), err.size() + 1);
  long differs_from_nominal = 0;
  for (std::size_t i = 1; i < n; ++i) {
    // The dt of tick i is the measured start-to-start time the thread records as period error.
    const double measured = (double(std::int64_t(std::llround(T * 1e9)) + err[i - 1])) * 1e-9;
    ASSERT_NEAR(spy.dt(i), measured, 1e-12) << "tick " << i;
    ASSERT_GT(spy.dt(i), 0.0);
    if (spy.dt(i) != T) ++differs_from_nominal;
  }
  EXPECT_GT(differs_from_nominal, 0) << "every dt was the nominal period: not measured";
}

// ---- Device safety: stale, refused, faults, ramp-in, clamp ----
namespace {
/// Pushes a constant force (0, 0, 1) N wherever the HIP is.
class ConstantForce final : public Renderer {
 public:
  const char* name() const override { return "constant"; }
  void reset() override { resets.fetch_add(1); }
  HriTick tick(const FieldView&, const Vec3&, double) override {
    HriTick t;
    t.force_n = {0, 0, 1};
    return t;
  }
  std::atomic<long> resets{0};
};

/// An asynchronous device the test steers: `fresh` reports arrive now, otherwise the last
/// one ages; `status` and `position` are what the next report says.
struct SteeredDevice final : HapticDeviceIO {
  std::atomic<bool> fresh{true};
  std::atomic<int> status{int(DeviceStatus::kOk)};
  std::atomic<double> z{0.0};
  std::atomic<std::uint32_t> connection{0};
  std::atomic<std::int64_t> last_ns{0};
  DeviceCaps c;
  Vec3 read_position_m() override { return read().position_m; }
  void write_force_n(const Vec3&) override {}
  DeviceCaps caps() const override { return c; }
  DeviceReading read() override {
    DeviceReading r;
    if (fresh.load()) last_ns.store(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                         std::chrono::steady_clock::now().time_since_epoch()).count());
    r.received_ns = last_ns.load();
    r.status = DeviceStatus(status.load());
    r.position_m = Vec3{0, 0, z.load()};
    r.connection = connection.load();
    return r;
  }
};

/// Keeps every tick's report age, status and sent force (preallocated; read after stop()).
struct TickLog final : TickObserver {
  static constexpr std::size_t kMax = 8192;
  std::array<std::int64_t, kMax> age_ns{};
  std::array<std::int64_t, kMax> t_ns{};
  std::array<DeviceStatus, kMax> status{};
  std::array<double, kMax> force{};
  std::array<double, kMax> dt_s{};  // what the renderer was given
  std::atomic<std::size_t> n{0};
  void on_tick(const TickRecord& r) noexcept override {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i >= kMax) return;
    t_ns[i] = r.t_ns;
    dt_s[i] = r.dt_s;
    age_ns[i] = r.t_ns - r.report_ns;
    status[i] = r.device_status;
    force[i] = norm(r.force_sent_n);
    n.store(i + 1, std::memory_order_release);
  }
};

struct SafetyRig {
  TripleBuffer<SampleField> published;
  ConstantForce renderer;
  SteeredDevice dev;
  TickLog log;
  std::unique_ptr<ServoThread> servo;
  explicit SafetyRig(double ramp_in_s = 0.0, double stale_restart_s = 0.02) {
    published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
    dev.c.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
    dev.c.workspace_max_m = Vec3{0.1, 0.1, 0.1};
    ServoThreadConfig cfg;
    cfg.rate_hz = 1000;
    cfg.sched_fifo = cfg.pin_cpu = cfg.lock_memory = false;
    cfg.observer = &log;
    cfg.ramp_in_s = ramp_in_s;
    cfg.stale_restart_s = stale_restart_s;
    servo = std::make_unique<ServoThread>(published, renderer, dev, cfg);
  }
  void run_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }
  /// Waits until the servo ran `k` more ticks (10 s at most): counts that do not depend on
  /// how much CPU a loaded machine leaves the servo thread.
  void run_ticks(std::size_t k) {
    const std::size_t target = log.n.load() + k;
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (log.n.load() < target && std::chrono::steady_clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
};
}  // namespace

TEST(ServoSafety, AStaleReportGivesZeroForceInTheSameTick) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ms(60);
  rig.dev.fresh = false;  // the device stops reporting
  rig.run_ms(60);
  rig.dev.fresh = true;
  rig.run_ms(60);
  rig.servo->stop();
  const std::size_t n = rig.log.n.load();
  ASSERT_GT(n, 100u);
  const std::int64_t timeout = 2'000'000;  // two periods at 1 kHz
  long stale = 0, forced = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (rig.log.age_ns[i] > timeout) {
      ++stale;
      EXPECT_EQ(rig.log.force[i], 0.0) << "tick " << i << ": a report " << rig.log.age_ns[i] << " ns old still forced";
      EXPECT_EQ(rig.log.status[i], DeviceStatus::kStale) << "tick " << i;
    } else if (rig.log.force[i] > 0) {
      ++forced;
    }
  }
  EXPECT_GT(stale, 30);   // the 60 ms without reports, less the timeout
  EXPECT_GT(forced, 60);  // before and after
  EXPECT_EQ(rig.servo->device_counters().stale, stale);
  EXPECT_GE(rig.renderer.resets.load(), 1);  // contact state forgotten before force came back
}

TEST(ServoSafety, AShortStaleBlipZeroesThoseTicksButKeepsTheContact) {
  SafetyRig rig(0.05, 0.2);  // blips up to 200 ms keep the contact state
  rig.servo->start();
  rig.run_ms(80);
  rig.dev.fresh = false;
  rig.run_ms(10);
  rig.dev.fresh = true;
  rig.run_ms(20);
  rig.servo->stop();
  const DeviceCounters c = rig.servo->device_counters();
  EXPECT_GT(c.stale, 0);
  EXPECT_EQ(c.ramps, 1);                     // only the one after enable
  EXPECT_EQ(rig.renderer.resets.load(), 0);  // the contact state was kept
  EXPECT_EQ(rig.log.force[rig.log.n.load() - 1], 1.0);  // straight back to the full force
}

// Across a stale blip that keeps the contact state the renderer was not ticked: its first
// tick after the blip is given the time since its last one (its velocity's time step), not
// the loop's last period.
TEST(ServoSafety, AfterAStaleBlipTheRendererIsGivenTheTimeSinceItLastRan) {
  SafetyRig rig(0.0, 0.2);  // blips up to 200 ms keep the contact state
  rig.servo->start();
  rig.run_ticks(40);
  rig.dev.fresh = false;
  rig.run_ms(12);
  rig.dev.fresh = true;
  rig.run_ticks(20);
  rig.servo->stop();
  const std::size_t n = rig.log.n.load();
  std::size_t last_ok = 0, checked = 0;
  bool in_blip = false;
  for (std::size_t i = 1; i < n; ++i) {
    if (rig.log.status[i] != DeviceStatus::kOk) {
      in_blip = true;
      continue;
    }
    if (in_blip) {  // the first renderer tick after the blip
      const double since_last = double(rig.log.t_ns[i] - rig.log.t_ns[last_ok]) * 1e-9;
      std::printf("after a blip of %zu ticks: dt given %.4f ms, since the renderer's last tick %.4f ms\n",
                  i - last_ok - 1, rig.log.dt_s[i] * 1e3, since_last * 1e3);
      EXPECT_EQ(rig.log.dt_s[i], since_last) << "tick " << i;
      EXPECT_GT(i - last_ok, 2u);
      ++checked;
      in_blip = false;
    }
    last_ok = i;
  }
  EXPECT_GE(checked, 1u);
  EXPECT_EQ(rig.renderer.resets.load(), 0);  // the contact state was kept
}

TEST(ServoSafety, NonFiniteOrOutOfWorkspaceReportsAreRefusedAndCounted) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ticks(30);  // ticks, not milliseconds: a loaded machine gives the servo fewer of them
  rig.dev.z = NAN;
  rig.run_ticks(30);
  rig.dev.z = 0.5;  // outside the +-0.1 m box
  rig.run_ticks(30);
  rig.dev.z = 0.0;
  rig.run_ticks(30);
  rig.servo->stop();
  const DeviceCounters c = rig.servo->device_counters();
  EXPECT_GT(c.refused, 50);  // 60 bad ticks, a tick or two at each change may go either way
  long refused_ticks = 0;
  for (std::size_t i = 0; i < rig.log.n.load(); ++i)
    if (rig.log.status[i] == DeviceStatus::kFault) {
      ++refused_ticks;
      EXPECT_EQ(rig.log.force[i], 0.0) << "tick " << i;
    }
  EXPECT_EQ(refused_ticks, c.refused);
}

TEST(ServoSafety, DisconnectedOrFaultyDeviceGetsZeroForce) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ticks(30);
  rig.dev.status = int(DeviceStatus::kDisconnected);
  rig.run_ticks(30);
  rig.dev.status = int(DeviceStatus::kFault);
  rig.run_ticks(30);
  rig.servo->stop();
  const DeviceCounters c = rig.servo->device_counters();
  EXPECT_GT(c.disconnected, 15);
  EXPECT_GT(c.fault, 15);
  for (std::size_t i = 0; i < rig.log.n.load(); ++i)
    if (rig.log.status[i] != DeviceStatus::kOk) {
      EXPECT_EQ(rig.log.force[i], 0.0) << "tick " << i;
    }
}

TEST(ServoSafety, ForceRampsInAfterEnableAndReconnection) {
  SafetyRig rig(0.05);
  rig.servo->start();
  rig.run_ticks(100);
  // The link comes back once the first ramp (50 ms) is over and the full force was sent.
  const auto full = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (rig.log.t_ns[rig.log.n.load() - 1] - rig.log.t_ns[0] < 60'000'000 && std::chrono::steady_clock::now() < full)
    rig.run_ticks(1);
  const std::size_t before = rig.log.n.load();
  rig.dev.connection = 1;
  rig.run_ticks(100);
  rig.servo->stop();
  const std::size_t n = rig.log.n.load();
  ASSERT_GT(n, before + 50);
  // The force is the renderer's 1 N times the ramp factor (tick time since enable) / 50 ms.
  const std::int64_t t0 = rig.log.t_ns[0];
  std::size_t ramped = 0;
  for (std::size_t i = 0; i < before; ++i) {
    const double expect = std::min(1.0, double(rig.log.t_ns[i] - t0) / 50e6);
    EXPECT_NEAR(rig.log.force[i], expect, 1e-9) << "tick " << i;
    if (expect > 0.0 && expect < 1.0) ++ramped;
  }
  EXPECT_GT(ramped, 5u);                              // the ramp spanned several ticks
  EXPECT_EQ(rig.log.force[before - 1], 1.0);          // ramped in: the full force
  EXPECT_EQ(rig.servo->device_counters().ramps, 2);
  // After the reconnection the force dropped and rose again.
  double lowest_after = 1.0;
  for (std::size_t i = before; i < n; ++i) lowest_after = std::min(lowest_after, rig.log.force[i]);
  EXPECT_LT(lowest_after, 0.1);
}

TEST(ServoSafety, ForceIsClampedToTheDeviceMaximum) {
  SafetyRig clamped;  // the limit set before start (caps are read at start)
  clamped.dev.c.max_force_n = 0.25;
  clamped.servo->start();
  clamped.run_ms(40);
  clamped.servo->stop();
  ASSERT_GT(clamped.log.n.load(), 20u);
  for (std::size_t i = 0; i < clamped.log.n.load(); ++i) EXPECT_LE(clamped.log.force[i], 0.25 + 1e-12);
  EXPECT_NEAR(clamped.log.force[clamped.log.n.load() - 1], 0.25, 1e-12);
  EXPECT_GT(clamped.servo->device_counters().clamped, 20);
}

// ---- Stalls: a late write restarts from zero; stop() gives up on a renderer that never returns ----
namespace {
std::int64_t mono_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

/// (0, 0, 1) N every tick; tick `slow_tick` takes `slow_ms`, or never returns until
/// `release` (slow_ms < 0). Records when it stalled and when it went on; bumps `stalls`
/// (if set) meanwhile, as a device's writer does when the servo stops writing.
class StallingForce final : public Renderer {
 public:
  const char* name() const override { return "stalling"; }
  void reset() override {}
  HriTick tick(const FieldView&, const Vec3&, double) override {
    if (++ticks_ == slow_tick) {
      start_ns.store(mono_ns());
      if (stalls) stalls->fetch_add(1);
      if (slow_ms >= 0) std::this_thread::sleep_for(std::chrono::milliseconds(slow_ms));
      while (slow_ms < 0 && !release.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      end_ns.store(mono_ns());
    }
    HriTick t;
    t.force_n = {0, 0, 1};
    return t;
  }
  long slow_tick = 100;
  int slow_ms = 10;
  std::atomic<bool> release{false};
  std::atomic<std::int64_t> start_ns{0}, end_ns{0};
  std::atomic<std::uint64_t>* stalls = nullptr;

 private:
  long ticks_ = 0;
};

/// A device that keeps every force it receives with its arrival time, and what
/// enable_force() last said (preallocated; read after stop()); its stall count is the
/// test's to bump.
struct ReceivingDevice final : HapticDeviceIO {
  static constexpr std::size_t kMax = 8192;
  std::array<std::int64_t, kMax> t_ns{};
  std::array<double, kMax> force{};
  std::atomic<std::size_t> n{0};
  std::atomic<int> enabled{-1};  // -1: never told
  Vec3 read_position_m() override { return {0.016, 0.016, 0.009}; }
  void write_force_n(const Vec3& f) override {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i >= kMax) return;
    t_ns[i] = mono_ns(), force[i] = norm(f);
    n.store(i + 1, std::memory_order_release);
  }
  const std::atomic<std::uint64_t>* enable_force(bool on, double) override {
    enabled.store(on ? 1 : 0);
    return &stalls;  // as a device with its own writer: it takes the force off when writes stop
  }
  std::atomic<std::uint64_t> stalls{0};
};

ServoThreadConfig stall_config() {
  ServoThreadConfig cfg;
  cfg.rate_hz = 1000;
  cfg.sched_fifo = true;  // where allowed: late ticks of a loaded machine restart the ramp too
  cfg.pin_cpu = cfg.lock_memory = false;
  cfg.ramp_in_s = 0.05;
  return cfg;
}

StallingForce g_never;  // outlives the abandoned thread (inside tick() until released)
ReceivingDevice g_never_device;
}  // namespace

TEST(ServoThread, ADeviceThatTookTheForceOffGetsARampFromZero) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
  StallingForce slow;  // tick 100 takes 10 ms; the device counts a stall meanwhile
  ReceivingDevice dev;
  slow.stalls = &dev.stalls;
  ServoThread servo(published, slow, dev, stall_config());
  servo.start();
  while (slow.end_ns.load() == 0 || dev.n.load() < 250) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(servo.stop(), "");
  // What the device received: the force before, then the write after the stall is an
  // exact zero and the force ramps in again from there (50 ms), back to full later.
  std::size_t late = 0;
  while (late < dev.n.load() && dev.t_ns[late] < slow.end_ns.load()) ++late;
  ASSERT_GT(late, 50u);
  ASSERT_LT(late + 100, dev.n.load());
  EXPECT_GT(dev.force[late - 1], 0.0);  // pushing when it stalled
  EXPECT_EQ(dev.force[late], 0.0) << "the write after the stall jumped back to full force";
  EXPECT_LT(dev.force[late + 1], 0.2) << "no ramp after the stall";
  EXPECT_LT(dev.force[late + 2], 0.2);
  EXPECT_EQ(*std::max_element(&dev.force[late + 60], &dev.force[dev.n.load() - 1]), 1.0);  // ramped in again
  EXPECT_GE(servo.device_counters().late_restarts, 1);
  EXPECT_EQ(dev.enabled.load(), 0);
}

TEST(ServoThread, StopGivesUpOnARendererThatNeverReturnsWithTheForceOff) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
  g_never.slow_tick = 20;
  g_never.slow_ms = -1;
  auto servo = std::make_unique<ServoThread>(published, g_never, g_never_device, stall_config());
  servo->start();
  while (g_never.start_ns.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(g_never_device.enabled.load(), 1);
  std::string error;
  std::atomic<bool> stopped{false};
  const auto t0 = std::chrono::steady_clock::now();
  std::thread stopper([&] {
    error = servo->stop();
    stopped.store(true);
  });
  while (!stopped.load() && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(3))
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!stopped.load()) g_never.release.store(true);  // stop() blocked: let it end, then fail
  stopper.join();
  ASSERT_LT(took, 1.0) << "stop() blocked on the stuck renderer";
  EXPECT_NE(error.find("the renderer has not returned"), std::string::npos) << error;
  EXPECT_EQ(g_never_device.enabled.load(), 0) << "the force was not turned off";
  EXPECT_THROW(servo->start(), std::logic_error);
  // Released after its servo is gone, the thread leaves without writing to the device.
  const std::size_t writes = g_never_device.n.load();
  servo.reset();
  g_never.release.store(true);
  while (g_never.end_ns.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(g_never_device.n.load(), writes);
}
