// The real-time servo thread: runs, reads snapshots a publisher swaps at full speed,
// allocates nothing on the servo thread (counted by a replaced operator new), renders real
// contact forces, passes the measured period to the renderer, leaves the device with an
// exact zero force, and stays quiet under ThreadSanitizer (the tsan preset runs this file).
// The safety tests (ServoSafety) judge what a logging device received, write by write;
// tests/mutants.sh breaks each guarded line and shows them fail.
#include <gtest/gtest.h>
#include <sys/mman.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include <time.h>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/sim/sim_device_io.h"

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
  EXPECT_EQ(note.find("mlock") != std::string::npos, !servo.memory_locked()) << note;
}

namespace {
// The sanitizers' runtimes make mlock a no-op that succeeds (VmLck stays 0).
#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
constexpr bool kMlockIsReal = false;
#else
constexpr bool kMlockIsReal = true;
#endif

/// A field of /proc/self/status [kB] (VmLck, VmRSS): the kernel's count, not the servo's.
long status_kb(const std::string& key) {
  std::ifstream f("/proc/self/status");
  for (std::string line; std::getline(f, line);)
    if (line.rfind(key + ":", 0) == 0) return std::stol(line.substr(key.size() + 1));
  return -1;
}
}  // namespace

// The servo locks what its ticks touch (its stack, record buffer and object), not the
// process: a 64 MiB "volume" loaded while it runs is not locked, and dropping it
// (MADV_DONTNEED, as an allocator returns freed memory) gives its pages back.
TEST(ServoThread, LocksWhatTheServoTouchesNotTheProcess) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
  HriRenderer renderer(HriParams{});
  ApproachingProbe dev;
  ServoThreadConfig cfg;
  cfg.rate_hz = 1000;
  cfg.sched_fifo = cfg.pin_cpu = false;
  cfg.record_ticks = 4096;
  const long before_kb = status_kb("VmLck");
  ServoThread servo(published, renderer, dev, cfg);
  const std::string note = servo.start();
  if (!servo.memory_locked()) GTEST_SKIP() << "memory locking refused here: " << note;
  const std::size_t big = std::size_t(64) << 20;
  void* volume = mmap(nullptr, big, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(volume, MAP_FAILED);
  std::memset(volume, 1, big);
  const long locked_kb = status_kb("VmLck") - before_kb;
  const long rss_loaded_kb = status_kb("VmRSS");
  const int dropped = madvise(volume, big, MADV_DONTNEED);
  const int dropped_errno = errno;
  const long rss_dropped_kb = status_kb("VmRSS");
  munmap(volume, big);
  servo.stop();
  // The servo's working set: the prefaulted stack and the frames above the loop (well under
  // 64 KiB), the record buffer, the ServoThread object, each rounded to pages.
  const long working_kb =
      long((kServoStackBytes + 16 * 1024 + 64 * 1024 + cfg.record_ticks * sizeof(std::int64_t) + sizeof(ServoThread)) /
           1024) + 3 * 4;
  std::printf("VmLck %ld kB (servo's working set at most %ld kB), RSS %ld kB -> %ld kB after the drop\n", locked_kb,
              working_kb, rss_loaded_kb, rss_dropped_kb);
  if (kMlockIsReal) {
    EXPECT_GT(locked_kb, 0);
    EXPECT_LE(locked_kb, working_kb) << "more than the servo's memory is locked";
  }
  EXPECT_EQ(dropped, 0) << "MADV_DONTNEED refused: " << std::strerror(dropped_errno);
  EXPECT_LT(rss_dropped_kb, rss_loaded_kb - long(big / 1024 / 2)) << "the dropped volume's pages stayed";
  EXPECT_EQ(status_kb("VmLck"), before_kb) << "stop() left memory locked";
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

// ---- Device safety: stale, lost, faulty and refused reports, a renderer's NaN or infinite
// force, ramp-in, clamp, pause, stop. Every check reads what the device received (each
// write_force_n, with its time), not what the servo says it sent. ----
namespace {
/// CLOCK_MONOTONIC [ns], the servo's clock.
std::int64_t mono_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

bool exact_zero(const Vec3& f) { return f.x == 0.0 && f.y == 0.0 && f.z == 0.0; }

std::string str(const Vec3& f) {
  char b[96];
  std::snprintf(b, sizeof b, "(%.17g, %.17g, %.17g) N", f.x, f.y, f.z);
  return b;
}

/// One servo tick as the device saw it: the report it handed out at read() and the force
/// it renders after that tick (its first write_force_n before the next read(); without one,
/// the force of the tick before goes on).
struct WireTick {
  std::int64_t read_ns = 0;         ///< when the servo read the report [ns]
  std::int64_t received_ns = 0;     ///< the report's receive time as handed out [ns]
  std::int64_t prev_write_ns = -1;  ///< the last write before this read (-1: none): the tick started after it [ns]
  DeviceStatus status = DeviceStatus::kOk;
  Vec3 position_m;                  ///< the report's position, device [m]
  std::uint32_t connection = 0;
  bool ticked = false;              ///< the renderer ran in this tick ...
  Vec3 rendered;                    ///< ... and answered this force [N]
  bool wrote = false;               ///< a write_force_n came in this tick
  Vec3 force;                       ///< the force the device renders after this tick [N]
  std::int64_t write_ns = 0;        ///< when that write came [ns]
};

/// One write_force_n as the device received it.
struct WireWrite {
  std::int64_t t_ns = 0;  ///< [ns]
  Vec3 force_n;           ///< [N]
  std::size_t reads = 0;  ///< reads before it
};

/// An asynchronous device the test steers (`fresh` reports arrive now, otherwise the last
/// one ages; `status`, `z` and `connection` are what the next report says) and that logs
/// every read and every write (preallocated; the log is read after stop()).
struct SteeredDevice final : HapticDeviceIO {
  static constexpr std::size_t kMax = 16384;
  std::atomic<bool> fresh{true};
  std::atomic<int> status{int(DeviceStatus::kOk)};
  std::atomic<double> z{0.0};
  std::atomic<std::uint32_t> connection{0};
  std::atomic<bool> watchdog_tripped{false};
  DeviceCaps c;
  std::vector<WireTick> ticks = std::vector<WireTick>(kMax);
  std::vector<WireWrite> writes = std::vector<WireWrite>(kMax);
  std::atomic<std::size_t> n_ticks{0}, n_writes{0};
  std::int64_t enabled_ns = -1;            ///< enable_force(true) [ns]
  long enabled_after = -1, disabled_after = -1;  ///< writes received before enable_force(true / false)
  WireTick* current = nullptr;             ///< the tick in progress (servo thread)

  Vec3 read_position_m() override { return Vec3{0, 0, z.load()}; }
  DeviceCaps caps() const override { return c; }
  const std::atomic<std::uint64_t>* enable_force(bool on, double) override {
    (on ? enabled_after : disabled_after) = long(n_writes.load());
    if (on) enabled_ns = mono_ns();
    return nullptr;  // keeps the last force: no writer of its own to stall
  }
  DeviceReading read() override {
    const std::int64_t now = mono_ns();
    if (fresh.load()) last_ns_ = now;
    DeviceReading r;
    r.received_ns = last_ns_;
    r.status = DeviceStatus(status.load());
    r.position_m = Vec3{0, 0, z.load()};
    r.connection = connection.load();
    r.watchdog_tripped = r.force_off = watchdog_tripped.load();
    const std::size_t i = n_ticks.load(std::memory_order_relaxed);
    current = nullptr;
    if (i < kMax) {
      WireTick& w = ticks[i];
      w = WireTick{now, r.received_ns, last_write_ns_, r.status, r.position_m, r.connection};
      w.force = held_;
      current = &w;
      n_ticks.store(i + 1, std::memory_order_release);
    }
    return r;
  }
  void write_force_n(const Vec3& f) override {
    const std::int64_t now = mono_ns();
    held_ = f;
    last_write_ns_ = now;
    const std::size_t i = n_writes.load(std::memory_order_relaxed);
    if (i < kMax) writes[i] = WireWrite{now, f, n_ticks.load(std::memory_order_relaxed)};
    n_writes.store(i + 1, std::memory_order_release);
    if (current && !current->wrote) {
      current->wrote = true;
      current->force = f;
      current->write_ns = now;
    }
  }
  /// The renderer's answer in the tick in progress.
  void note_rendered(const Vec3& f) {
    if (!current) return;
    current->ticked = true;
    current->rendered = f;
  }
  std::size_t logged() const { return std::min(n_ticks.load(), kMax); }

 private:
  std::int64_t last_ns_ = 0;
  std::int64_t last_write_ns_ = -1;
  Vec3 held_;
};

/// Pushes the force the test sets (default (0, 0, 1) N) wherever the HIP is; tells the
/// device what it answered.
class SteeredForce final : public Renderer {
 public:
  explicit SteeredForce(SteeredDevice& dev) : dev_(dev) {}
  const char* name() const override { return "steered"; }
  void reset() override { resets.fetch_add(1); }
  HriTick tick(const FieldView&, const Vec3&, double) override {
    HriTick t;
    t.force_n = {fx.load(), fy.load(), fz.load()};
    t.fault = fault.load();
    dev_.note_rendered(t.force_n);
    return t;
  }
  void set(const Vec3& f) {
    fx = f.x;
    fy = f.y;
    fz = f.z;
  }
  std::atomic<double> fx{0}, fy{0}, fz{1};
  std::atomic<bool> fault{false};  ///< the renderer reports a fault (with the force set)
  std::atomic<long> resets{0};

 private:
  SteeredDevice& dev_;
};

/// Keeps every tick's start and the dt the renderer was given (preallocated; read after stop()).
struct TickLog final : TickObserver {
  static constexpr std::size_t kMax = 8192;
  std::array<std::int64_t, kMax> t_ns{};
  std::array<DeviceStatus, kMax> status{};
  std::array<double, kMax> dt_s{};
  std::atomic<std::size_t> n{0};
  void on_tick(const TickRecord& r) noexcept override {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i >= kMax) return;
    t_ns[i] = r.t_ns;
    dt_s[i] = r.dt_s;
    status[i] = r.device_status;
    n.store(i + 1, std::memory_order_release);
  }
};

constexpr double kRateHz = 1000;
constexpr std::int64_t kStaleNs = 2'000'000;  // the default stale timeout: two periods at 1 kHz

struct SafetyRig {
  TripleBuffer<SampleField> published;
  SteeredDevice dev;
  SteeredForce renderer{dev};
  TickLog log;
  std::unique_ptr<ServoThread> servo;
  double ramp_in_s;
  /// rate_n_per_s: the gate's rate limit (default: none to speak of, so that each other rule
  /// is seen alone); scene_limit_n: ServoThreadConfig::force_limit_n.
  explicit SafetyRig(double ramp_in_s_ = 0.0, double stale_restart_s = 0.02, double max_force_n = INFINITY,
                     double rate_n_per_s = 1e12, double scene_limit_n = INFINITY)
      : ramp_in_s(ramp_in_s_) {
    published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
    dev.c.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
    dev.c.workspace_max_m = Vec3{0.1, 0.1, 0.1};
    dev.c.max_force_n = max_force_n;  // caps are read at start()
    ServoThreadConfig cfg;
    cfg.rate_hz = kRateHz;
    cfg.sched_fifo = cfg.pin_cpu = cfg.lock_memory = false;
    cfg.observer = &log;
    cfg.ramp_in_s = ramp_in_s;
    cfg.stale_restart_s = stale_restart_s;
    cfg.max_force_rate_n_per_s = rate_n_per_s;
    cfg.force_limit_n = scene_limit_n;
    servo = std::make_unique<ServoThread>(published, renderer, dev, cfg);
  }
  void run_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }
  /// Waits until the servo read the device `k` more times (10 s at most): counts that do
  /// not depend on how much CPU a loaded machine leaves the servo thread.
  void run_ticks(std::size_t k) {
    const std::size_t target = dev.n_ticks.load() + k;
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (dev.n_ticks.load() < target && std::chrono::steady_clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
};

/// What the device received, tick by tick, against the safety rules.
struct WireCheck {
  long zeroed = 0;     ///< ticks that had to give an exact zero force in that tick (and did)
  long stale = 0;      ///< of those: the report was surely older than the timeout
  long lost = 0;       ///< the device said disconnected or fault
  long refused = 0;    ///< the position was non-finite or outside the workspace
  long nonfinite = 0;  ///< the renderer answered a non-finite force
  long forced = 0;     ///< fresh good ticks that got exactly `full`
  long failures = 0;
};

/// Checks every logged tick: a tick whose report the device knows to be bad (status not ok,
/// a position outside its workspace, older than the stale timeout at the tick's start, which
/// is after the write before it) or whose renderer answered a non-finite force got an exact
/// zero force written within that tick; every write is finite and within the device's
/// maximum; with `full` given, every fresh good tick got exactly that force.
WireCheck check_wire(const SteeredDevice& d, const Vec3* full = nullptr) {
  WireCheck w;
  auto fail = [&](std::size_t i, const char* what) {
    if (++w.failures <= 10) ADD_FAILURE() << "tick " << i << ": " << what << "; the device got " << str(d.ticks[i].force);
  };
  for (std::size_t i = 0; i < d.logged(); ++i) {
    const WireTick& t = d.ticks[i];
    const bool stale = t.prev_write_ns >= 0 && t.prev_write_ns - t.received_ns > kStaleNs;
    const bool lost = t.status != DeviceStatus::kOk;
    const bool refused = !d.c.contains(t.position_m);
    const bool nonfinite = t.ticked && !finite(t.rendered);
    if (stale || lost || refused || nonfinite) {
      if (!t.wrote) fail(i, "a bad tick wrote no force (the one before goes on)");
      else if (!exact_zero(t.force)) fail(i, "a bad tick's force is not an exact zero");
      else ++w.zeroed;
      w.stale += stale;
      w.lost += lost;
      w.refused += refused && !lost;
      w.nonfinite += nonfinite;
    } else if (full && t.received_ns == t.read_ns && t.ticked) {
      if (!t.wrote || t.force.x != full->x || t.force.y != full->y || t.force.z != full->z)
        fail(i, "a good tick did not get the renderer's force");
      else ++w.forced;
    }
  }
  for (std::size_t i = 0; i < std::min(d.n_writes.load(), SteeredDevice::kMax); ++i) {
    const Vec3& f = d.writes[i].force_n;
    if (!finite(f) || !(norm(f) <= d.c.max_force_n + 1e-12)) {
      if (++w.failures <= 20) ADD_FAILURE() << "write " << i << ": " << str(f) << " (limit " << d.c.max_force_n << " N)";
    }
  }
  return w;
}

/// Checks a ramp-in of the renderer's 1 N over ramp_s that starts at tick `from` (its first
/// good tick): the device got an exact zero there, then |F| = (t - t_from) / ramp_s up to 1 N,
/// where the tick starts t lie between the write before each read and the read itself;
/// `start_ns` is the latest time known before t_from. Up to the next outage or reconnection.
/// Returns the ticks inside the ramp (a starved servo thread may have none: the exact zero at
/// the start and the bounds are the test).
long check_ramp(const SteeredDevice& d, std::size_t from, double ramp_s, std::int64_t start_ns) {
  const WireTick& first = d.ticks[from];
  EXPECT_TRUE(first.wrote && exact_zero(first.force)) << "tick " << from << ": the ramp starts at " << str(first.force);
  long inside = 0;
  for (std::size_t i = from + 1; i < d.logged(); ++i) {
    if (d.ticks[i].status != DeviceStatus::kOk || d.ticks[i].connection != first.connection) break;  // the next outage
    const WireTick& t = d.ticks[i];
    const double f = norm(t.force);
    const double hi = std::min(1.0, double(t.read_ns - start_ns) * 1e-9 / ramp_s);
    const double lo = std::min(1.0, double(t.prev_write_ns - first.read_ns) * 1e-9 / ramp_s);
    EXPECT_LE(f, hi + 1e-9) << "tick " << i << " (" << i - from << " into the ramp)";
    EXPECT_GE(f, lo - 1e-9) << "tick " << i << " (" << i - from << " into the ramp)";
    inside += f > 0 && f < 1;
  }
  return inside;
}
}  // namespace

TEST(ServoSafety, AStaleReportGivesZeroForceInTheSameTick) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ticks(60);
  rig.dev.fresh = false;  // the device stops reporting
  rig.run_ticks(60);
  rig.dev.fresh = true;
  rig.run_ticks(60);
  rig.servo->stop();
  const Vec3 full{0, 0, 1};
  const WireCheck w = check_wire(rig.dev, &full);
  EXPECT_GT(w.stale, 50);   // the 60 ticks without reports, less the timeout
  EXPECT_GT(w.forced, 100);  // before and after
  EXPECT_GE(rig.servo->device_counters().stale, w.stale);
  EXPECT_GE(rig.renderer.resets.load(), 1);  // contact state forgotten before force came back
}

TEST(ServoSafety, TheDevicesOwnStaleTimeoutHolds) {
  // A device whose readings come every few servo periods (a network stream) says how old a
  // reading may get (DeviceCaps::stale_timeout_s, here 200 ms): readings older than the
  // default two periods still give force; older than 200 ms, an exact zero.
  SafetyRig rig;
  rig.dev.c.stale_timeout_s = 0.2;  // caps are read at start()
  rig.servo->start();
  rig.run_ticks(60);
  rig.dev.fresh = false;
  rig.run_ms(400);
  rig.dev.fresh = true;
  rig.run_ticks(30);
  rig.servo->stop();
  long aged_forced = 0, past_zero = 0, past = 0;
  for (std::size_t i = 0; i < rig.dev.logged(); ++i) {
    const WireTick& t = rig.dev.ticks[i];
    if (t.prev_write_ns < 0 || !t.wrote) continue;
    const std::int64_t age = t.prev_write_ns - t.received_ns;  // the tick started after this
    if (age > 3 * kStaleNs && t.read_ns - t.received_ns < 190'000'000) aged_forced += !exact_zero(t.force);
    if (age > 201'000'000) past += 1, past_zero += exact_zero(t.force);
  }
  EXPECT_GT(aged_forced, 50) << "readings 6 to 190 ms old must still give force with the device's 200 ms timeout";
  EXPECT_GT(past, 50);
  EXPECT_EQ(past_zero, past) << "a reading older than the device's timeout gave force";
  EXPECT_GT(rig.servo->device_counters().stale, 50);
}

TEST(ServoSafety, AShortStaleBlipZeroesThoseTicksButKeepsTheContact) {
  SafetyRig rig(0.05, 2.0);  // blips up to 2 s (a loaded machine stretches 10 ticks) keep the contact state
  rig.servo->start();
  rig.run_ms(80);
  rig.dev.fresh = false;
  rig.run_ticks(10);
  rig.dev.fresh = true;
  rig.run_ticks(20);
  rig.servo->stop();
  const WireCheck w = check_wire(rig.dev);
  EXPECT_GT(w.stale, 0);
  const DeviceCounters c = rig.servo->device_counters();
  EXPECT_EQ(c.ramps, 1);                     // only the one after enable
  EXPECT_EQ(rig.renderer.resets.load(), 0);  // the contact state was kept
  const WireTick& last = rig.dev.ticks[rig.dev.logged() - 1];
  EXPECT_TRUE(last.wrote);
  EXPECT_EQ(last.force.z, 1.0);  // straight back to the full force
}

// Across a stale blip that keeps the contact state the renderer was not ticked: its first
// tick after the blip is given the time since its last one (its velocity's time step), not
// the loop's last period.
TEST(ServoSafety, AfterAStaleBlipTheRendererIsGivenTheTimeSinceItLastRan) {
  SafetyRig rig(0.0, 2.0);  // blips up to 2 s (a loaded machine stretches 10 ticks) keep the contact state
  rig.servo->start();
  rig.run_ticks(40);
  rig.dev.fresh = false;
  rig.run_ticks(10);
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
  const Vec3 full{0, 0, 1};
  EXPECT_GT(check_wire(rig.dev, &full).stale, 0);
}

TEST(ServoSafety, NonFiniteOrOutOfWorkspaceReportsAreRefusedAndCounted) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ticks(30);  // ticks, not milliseconds: a loaded machine gives the servo fewer of them
  rig.dev.z = NAN;
  rig.run_ticks(30);
  rig.dev.z = 0.1000001;  // just outside the +-0.1 m box
  rig.run_ticks(30);
  rig.dev.z = -0.1000001;
  rig.run_ticks(30);
  rig.dev.z = 0.1;  // on its face: inside
  rig.run_ticks(30);
  rig.servo->stop();
  const Vec3 full{0, 0, 1};
  const WireCheck w = check_wire(rig.dev, &full);
  EXPECT_GE(w.refused, 90);
  EXPECT_GE(w.forced, 50);
  EXPECT_EQ(rig.servo->device_counters().refused, w.refused);
}

// Each outage gives an exact zero in its own ticks; when the device is good again the
// force ramps in afresh from an exact zero.
TEST(ServoSafety, DisconnectedOrFaultyDeviceGetsZeroForceThenRampsIn) {
  const double ramp_s = 0.05;
  SafetyRig rig(ramp_s);
  rig.servo->start();
  rig.run_ticks(80);
  for (const DeviceStatus bad : {DeviceStatus::kDisconnected, DeviceStatus::kFault}) {
    rig.dev.status = int(bad);
    rig.run_ticks(30);
    rig.dev.status = int(DeviceStatus::kOk);
    rig.run_ticks(80);
  }
  rig.servo->stop();
  const WireCheck w = check_wire(rig.dev);
  EXPECT_GE(w.lost, 58);
  const DeviceCounters c = rig.servo->device_counters();
  EXPECT_EQ(c.disconnected + c.fault, w.lost);
  long recoveries = 0;
  for (std::size_t i = 1; i < rig.dev.logged(); ++i)
    if (rig.dev.ticks[i - 1].status != DeviceStatus::kOk && rig.dev.ticks[i].status == DeviceStatus::kOk) {
      ++recoveries;
      std::printf("recovery at tick %zu: %ld ticks inside the ramp\n", i, check_ramp(rig.dev, i, ramp_s, rig.dev.ticks[i].prev_write_ns));
    }
  EXPECT_EQ(recoveries, 2);
}

TEST(ServoSafety, ForceRampsInAfterEnableAndReconnection) {
  const double ramp_s = 0.05;
  SafetyRig rig(ramp_s);
  rig.servo->start();
  rig.run_ms(70);  // the first ramp (50 ms) is over
  rig.run_ticks(20);
  rig.dev.connection = 1;  // the link came back
  rig.run_ticks(100);
  rig.servo->stop();
  const SteeredDevice& d = rig.dev;
  EXPECT_EQ(d.enabled_after, 0);  // force enabled before the first write
  std::printf("enable: %ld ticks inside the ramp\n", check_ramp(d, 0, ramp_s, d.enabled_ns));
  std::size_t back = 0;
  while (back < d.logged() && d.ticks[back].connection == 0) ++back;
  ASSERT_LT(back + 50, d.logged());
  EXPECT_EQ(d.ticks[back - 1].force.z, 1.0);  // ramped in: the full force before the link came back
  std::printf("reconnection: %ld ticks inside the ramp\n", check_ramp(d, back, ramp_s, d.ticks[back].prev_write_ns));
  EXPECT_EQ(rig.servo->device_counters().ramps, 2);
}

// |F| just above the device's maximum is clamped to it, its direction kept; just below
// it passes unchanged.
TEST(ServoSafety, ForceIsClampedToTheDeviceMaximum) {
  const Vec3 f{0.6, 0, 0.8};  // |F| = 1 N
  for (const double max_n : {0.99, 1.01}) {
    SafetyRig rig(0.0, 0.02, max_n);
    rig.renderer.set(f);
    rig.servo->start();
    rig.run_ticks(40);
    rig.servo->stop();
    const WireCheck w = check_wire(rig.dev);  // every write within max_n
    EXPECT_EQ(w.failures, 0);
    long good = 0;
    for (std::size_t i = 0; i < rig.dev.logged(); ++i) {
      const WireTick& t = rig.dev.ticks[i];
      if (!t.ticked) continue;
      ++good;
      ASSERT_TRUE(t.wrote) << "tick " << i;
      if (max_n < 1) {
        EXPECT_NEAR(norm(t.force), max_n, 1e-12) << "tick " << i;
        EXPECT_NEAR(norm(cross(t.force, f)), 0.0, 1e-12) << "tick " << i << ": turned";
        EXPECT_GT(dot(t.force, f), 0.0) << "tick " << i;
      } else {
        EXPECT_TRUE(t.force.x == f.x && t.force.y == f.y && t.force.z == f.z) << "tick " << i << ": " << str(t.force);
      }
    }
    EXPECT_GT(good, 30) << max_n;
    const long clamped = rig.servo->device_counters().clamped;
    if (max_n < 1) EXPECT_EQ(clamped, good);
    else EXPECT_EQ(clamped, 0);
  }
}

// The scene's force limit below the device's peak: the device gets at most the scene's limit,
// the direction kept (the gate clamps to min(scene, device)).
TEST(ServoSafety, TheScenesLimitBelowTheDevicesPeakHolds) {
  const Vec3 f{0.6, 0, 0.8};  // |F| = 1 N
  SafetyRig rig(0.0, 0.02, 5.0, 1e12, 0.7);
  rig.renderer.set(f);
  rig.servo->start();
  rig.run_ticks(40);
  rig.servo->stop();
  long good = 0;
  for (std::size_t i = 0; i < rig.dev.logged(); ++i) {
    const WireTick& t = rig.dev.ticks[i];
    if (!t.ticked) continue;
    ++good;
    EXPECT_NEAR(norm(t.force), 0.7, 1e-12) << "tick " << i;
    EXPECT_NEAR(norm(cross(t.force, f)), 0.0, 1e-12) << "tick " << i << ": turned";
  }
  EXPECT_GT(good, 30);
  EXPECT_EQ(rig.servo->device_counters().clamped, good);
}

// A step demand (0 -> 1 N, then 1 N turned by 90 degrees, then 0 -> 1 N after a fault's
// zero ticks) reaches the device at the rate limit: between two ticks the force sent changes
// by at most rate x (the ticks' starts apart), judged on what the device received, and the
// steps take several ticks (counted).
TEST(ServoSafety, AStepDemandReachesTheDeviceAtTheRateLimit) {
  constexpr double kRate = 50;  // N/s: 1 N in 20 ms, 20 ticks at 1 kHz
  SafetyRig rig(0.0, 0.02, 3.3, kRate);
  rig.renderer.set({0, 0, 0});
  rig.servo->start();
  rig.run_ticks(20);
  rig.renderer.set({0, 0, 1});
  rig.run_ticks(60);
  rig.renderer.set({1, 0, 0});
  rig.run_ticks(60);
  rig.dev.status = int(DeviceStatus::kFault);
  rig.run_ticks(10);
  rig.dev.status = int(DeviceStatus::kOk);
  rig.run_ticks(60);
  rig.servo->stop();
  // Judged by the ticks' own start times (TickLog), so a loaded machine's late ticks change
  // the figures, not the verdict.
  const std::size_t n = std::min(rig.dev.logged(), rig.log.n.load());
  long limited_checks = 0, rises = 0;
  std::int64_t zero_at = -1;  // the start of the last tick that sent an exact zero
  for (std::size_t i = 1; i < n; ++i) {
    const WireTick &a = rig.dev.ticks[i - 1], &b = rig.dev.ticks[i];
    if (!a.wrote || !b.wrote) continue;
    const double dt = double(rig.log.t_ns[i] - rig.log.t_ns[i - 1]) * 1e-9;
    const bool zero_tick = b.status != DeviceStatus::kOk;  // a fault's zero is at once, by design
    if (!zero_tick) {
      ++limited_checks;
      EXPECT_LE(norm(b.force - a.force), kRate * dt + 1e-9) << "tick " << i << ": " << str(a.force) << " -> " << str(b.force);
    } else {
      EXPECT_TRUE(exact_zero(b.force)) << "tick " << i;
    }
    if (exact_zero(b.force)) zero_at = rig.log.t_ns[i];
    // A rise from zero to the full 1 N took at least 1 N / rate = 20 ms of the ticks' time.
    if (zero_at >= 0 && norm(b.force) >= 1.0 - 1e-12) {
      ++rises;
      EXPECT_GE(double(rig.log.t_ns[i] - zero_at) * 1e-9, 1.0 / kRate - 1e-9) << "tick " << i << ": a rise faster than the rate";
      zero_at = -1;
    }
  }
  EXPECT_GT(limited_checks, 150);
  EXPECT_EQ(rises, 2) << "the step and the rise after the fault";
  EXPECT_GE(rig.servo->device_counters().rate_limited, 2);
}

// A device that applies each force in its own loop (an SDK's scheduler) at 1 kHz refuses a
// 2 kHz servo before anything starts (its ticks between two device frames would be lost, and
// its stall rule acts in the device's periods); at 1 kHz it runs.
TEST(ServoSafety, AServoFasterThanTheDevicesOwnLoopIsRefused) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
  SteeredDevice dev;
  dev.c.output_rate_hz = 1000;
  SteeredForce renderer{dev};
  ServoThreadConfig cfg;
  cfg.sched_fifo = cfg.pin_cpu = cfg.lock_memory = false;
  cfg.rate_hz = 2000;
  {
    ServoThread servo(published, renderer, dev, cfg);
    try {
      servo.start();
      FAIL() << "a 2 kHz servo started on a 1 kHz device loop";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("1000"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(dev.n_writes.load(), 0u) << "the refused servo wrote to the device";
  cfg.rate_hz = 1000;
  ServoThread servo(published, renderer, dev, cfg);
  servo.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  servo.stop();
  EXPECT_GT(dev.n_writes.load(), 5u);
}

// With a rate limit (50 N/s: a release from 1 N would take 20 ms), three things still stop
// the force at once, an exact zero in the very tick: the device saying its force is off (its
// watchdog tripped), and a renderer reporting a fault (whatever force it answers).
TEST(ServoSafety, AFaultOrTheDevicesForceOffIsAnExactZeroInThatTickDespiteTheRateLimit) {
  SafetyRig rig(0.05, 0.02, 3.3, 50);
  rig.servo->start();
  rig.run_ticks(80);  // 1 N reached (the 50 ms ramp-in, slower than 50 N/s)
  const std::size_t before_trip = rig.dev.logged();
  rig.dev.watchdog_tripped = true;
  rig.run_ticks(20);
  const std::size_t tripped = rig.dev.logged();
  rig.dev.watchdog_tripped = false;
  rig.run_ticks(80);  // ramped in again
  const std::size_t before_fault = rig.dev.logged();
  rig.renderer.fault = true;  // still answering (0, 0, 1) N
  rig.run_ticks(20);
  const std::size_t faulted = rig.dev.logged();
  rig.renderer.fault = false;
  rig.run_ticks(20);
  rig.servo->stop();
  ASSERT_EQ(rig.dev.ticks[before_trip - 1].force.z, 1.0) << "1 N before the trip";
  // The tick in progress when the flag was set may not have read it: from the next one on.
  for (std::size_t i = before_trip + 1; i < tripped; ++i)
    EXPECT_TRUE(exact_zero(rig.dev.ticks[i].force)) << "tick " << i << " after the trip: " << str(rig.dev.ticks[i].force);
  ASSERT_EQ(rig.dev.ticks[before_fault - 1].force.z, 1.0) << "1 N again before the fault";
  for (std::size_t i = before_fault + 1; i < faulted; ++i)
    EXPECT_TRUE(exact_zero(rig.dev.ticks[i].force)) << "tick " << i << " of the fault: " << str(rig.dev.ticks[i].force);
}

// A renderer that answers NaN or an infinite force: the device gets an exact zero in those
// ticks (with and without a finite force limit), and the renderer's force again after.
TEST(ServoSafety, ANonFiniteForceFromTheRendererSendsZero) {
  const double inf = std::numeric_limits<double>::infinity();
  for (const double max_n : {inf, 10.0}) {
    SafetyRig rig(0.0, 0.02, max_n);
    rig.servo->start();
    rig.run_ticks(20);
    for (const Vec3 bad : {Vec3{NAN, 0, 1}, Vec3{0, 0, inf}, Vec3{-inf, 0, 0}, Vec3{0, NAN, -inf}}) {
      rig.renderer.set(bad);
      rig.run_ticks(20);
      rig.renderer.set({0, 0, 1});
      rig.run_ticks(20);
    }
    rig.servo->stop();
    const Vec3 full{0, 0, 1};
    const WireCheck w = check_wire(rig.dev, &full);
    EXPECT_GE(w.nonfinite, 70) << "limit " << max_n;
    EXPECT_GE(w.forced, 70) << "limit " << max_n;
  }
}

// Paused: every tick writes an exact zero; resumed: the renderer's force again.
TEST(ServoSafety, PausedTicksGetZeroForce) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ticks(30);
  rig.servo->pause(true);
  const std::size_t a = rig.dev.n_ticks.load();
  rig.run_ticks(30);
  const std::size_t b = rig.dev.n_ticks.load();
  rig.servo->pause(false);
  rig.run_ticks(30);
  rig.servo->stop();
  const Vec3 full{0, 0, 1};
  check_wire(rig.dev, &full);
  ASSERT_GT(b, a + 20);
  for (std::size_t i = a + 1; i < b; ++i) {
    const WireTick& t = rig.dev.ticks[i];
    EXPECT_TRUE(t.wrote && exact_zero(t.force)) << "paused tick " << i << ": the device got " << str(t.force);
  }
  EXPECT_EQ(rig.dev.ticks[rig.dev.logged() - 1].force.z, 1.0);
}

// After the last tick the device is sent an exact zero, and only then is its force disabled.
TEST(ServoSafety, StopLeavesTheDeviceWithAnExactZeroThenDisablesIt) {
  SafetyRig rig;
  rig.servo->start();
  rig.run_ticks(50);
  rig.servo->stop();
  const SteeredDevice& d = rig.dev;
  const std::size_t n = d.n_writes.load();
  ASSERT_GT(n, 40u);
  ASSERT_LT(n, SteeredDevice::kMax);
  EXPECT_EQ(d.writes[n - 2].force_n.z, 1.0);     // the last tick's force ...
  EXPECT_TRUE(exact_zero(d.writes[n - 1].force_n)) << "the device was left with " << str(d.writes[n - 1].force_n);
  EXPECT_EQ(d.writes[n - 1].reads, d.n_ticks.load());  // ... then, after the last read, zero
  EXPECT_EQ(d.disabled_after, long(n));          // disabled after that zero
}

TEST(ServoSafety, AfterTheDeviceWatchdogTrippedTheForceRampsInFromZero) {
  SafetyRig rig(0.05);
  rig.servo->start();
  rig.run_ticks(120);  // past the 50 ms ramp-in (the log is read only after stop())
  const std::size_t before = rig.dev.logged();
  rig.dev.watchdog_tripped = true;  // the device zeroed its force and says so
  rig.run_ticks(30);
  const std::size_t tripped = rig.dev.logged();
  rig.dev.watchdog_tripped = false;  // the host's reports reached it again: force back on
  rig.run_ticks(100);
  rig.servo->stop();
  const std::size_t n = rig.dev.logged();
  ASSERT_GT(n, tripped + 80);
  ASSERT_GT(before, 2u);
  EXPECT_EQ(rig.dev.ticks[before - 2].force.z, 1.0) << "the full force before the trip";
  // What the device received in the ticks that read the tripped flag: nothing but zero
  // (one tick may straddle the change).
  for (std::size_t i = tripped - 25; i < tripped; ++i)
    EXPECT_EQ(rig.dev.ticks[i].force.z, 0.0) << "tick " << i;
  // Back on: the force starts from 0 and grows over the 50 ms ramp to the full 1 N, judged by
  // the ticks' own times (a loaded machine runs fewer, later ticks): the first tick with
  // force has at most (its read - the write before the last zero tick) / 50 ms, and the full
  // force comes no sooner than 50 ms after the last zero tick began.
  std::size_t last_zero = tripped - 1;
  while (last_zero + 1 < n && rig.dev.ticks[last_zero + 1].force.z == 0.0) ++last_zero;
  ASSERT_LT(last_zero + 1, n) << "the force never came back";
  const WireTick &z = rig.dev.ticks[last_zero], &first = rig.dev.ticks[last_zero + 1];
  EXPECT_LE(first.force.z, double(first.read_ns - z.prev_write_ns) * 1e-9 / 0.05 + 1e-9) << "a jump, not a ramp";
  std::size_t full = last_zero + 1;
  while (full < n && rig.dev.ticks[full].force.z < 1.0) ++full;
  ASSERT_LT(full, n) << "the ramp never reached the full force";
  EXPECT_GE(double(rig.dev.ticks[full].read_ns - z.prev_write_ns) * 1e-9, 0.05 - 1e-9) << "the ramp was shorter than 50 ms";
  EXPECT_EQ(rig.dev.ticks[n - 1].force.z, 1.0);
}

// ---- Stalls: a late write restarts from zero; stop() gives up on a renderer that never returns ----
namespace {
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
  EXPECT_FALSE(servo->abandoned());
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
  EXPECT_TRUE(servo->abandoned());
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

namespace {
/// A link that sends a pose each millisecond on its own schedule and waits for the force:
/// every 20th pose 300 us late. Its phase (when the next pose is due, servo/input_phase.h)
/// is the schedule's own; it keeps the newest pose's number each tick read (preallocated).
struct PacedLink final : HapticDeviceIO {
  static constexpr std::int64_t kPeriodNs = 1'000'000, kLateNs = 300'000;
  static constexpr std::size_t kMax = 8192;
  std::int64_t t0_ns = 0;                 // pose k is due at t0_ns + k periods
  std::atomic<std::uint64_t> delivered{0};  // poses arrived; the newest is number delivered - 1
  std::array<std::uint64_t, kMax> newest_read{};
  std::atomic<std::size_t> reads{0};
  static bool late(std::uint64_t k) { return k % 20 == 19; }
  Vec3 read_position_m() override { return {0.016, 0.016, 0.030}; }  // far above the floor: no force
  DeviceReading read() override {
    DeviceReading d;
    d.position_m = read_position_m();
    d.sequence = delivered.load();
    if (const std::size_t i = reads.load(std::memory_order_relaxed); i < kMax) {
      newest_read[i] = d.sequence;
      reads.store(i + 1, std::memory_order_release);
    }
    return d;
  }
  void write_force_n(const Vec3&) override {}
  InputPhase input_phase() const override {
    return {t0_ns + std::int64_t(delivered.load()) * kPeriodNs, kPeriodNs, 0};
  }
  /// Delivers poses 0 .. n-1 on the schedule (this thread sleeps to each arrival).
  void feed(std::uint64_t n) {
    for (std::uint64_t k = 0; k < n; ++k) {
      const std::int64_t at = t0_ns + std::int64_t(k) * kPeriodNs + (late(k) ? kLateNs : 0);
      const timespec ts{time_t(at / 1000000000LL), long(at % 1000000000LL)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
      delivered.store(k + 1);
    }
  }
};
}  // namespace

// A pose 300 us late, past the tick placed 100 us after it was due: the tick waits for it
// (servo/input_phase.h, input_wait_until) and reads it while it is the newest. Without the
// wait the next pose, on time, comes first and the late one is never read.
TEST(ServoThread, ATickWaitsForALatePoseInsteadOfLeavingItToTheNext) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(plane_field({0, 0, 1}, {0.016, 0.016, 0.010})));
  HriParams hp;
  HriRenderer renderer(hp);
  PacedLink link;
  ServoThreadConfig cfg = stall_config();
  cfg.ramp_in_s = 0;
  cfg.input_lead_us = 100;
  link.t0_ns = mono_ns() + 20'000'000;
  ServoThread servo(published, renderer, link, cfg);
  servo.start();
  link.feed(1500);
  EXPECT_EQ(servo.stop(), "");
  // The late poses after the first 200 (the ticks have moved to the stream's phase by then):
  // each read by a tick while it was the newest.
  std::vector<bool> seen(1501, false);
  for (std::size_t i = 0; i < link.reads.load(); ++i) seen[std::size_t(link.newest_read[i])] = true;
  int late = 0, read = 0;
  for (std::uint64_t k = 200; k + 1 < 1500; ++k)
    if (PacedLink::late(k)) ++late, read += seen[std::size_t(k + 1)];
  EXPECT_GT(servo.input_waits(), 0);
  EXPECT_GE(read, late * 4 / 5) << read << " of " << late << " late poses read while the newest ("
                                << servo.input_waits() << " waits, " << servo.input_wait_timeouts() << " in vain)";
}
