// The real-time servo thread: runs, reads snapshots a publisher swaps at full speed,
// allocates nothing on the servo thread (counted by a replaced operator new), and stays
// quiet under ThreadSanitizer (the tsan preset runs this file).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <new>
#include <thread>

#include "analytic_fields.h"
#include "servo_thread.h"

using namespace isotouch::servo;

namespace {
thread_local bool t_is_servo = false;
std::atomic<long> g_servo_allocations{0};
}  // namespace

void* operator new(std::size_t n) {
  if (t_is_servo) g_servo_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

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

  ServoThreadConfig cfg;
  cfg.rate_hz = hp.rate_hz;
  cfg.record_ticks = 10000;
  cfg.on_thread_start = [] { t_is_servo = true; };
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
  servo.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  servo.stop();
  stop = true;
  publisher.join();

  EXPECT_GT(servo.ticks(), 500);                   // ran (2 kHz for 1.5 s = 3000 nominal)
  EXPECT_GT(servo.snapshot_changes(), 10);         // and saw the publisher's snapshots
  EXPECT_GT(publications.load(), 10);
  EXPECT_EQ(servo.faults(), 0);
  EXPECT_EQ(g_servo_allocations.load(), 0) << "the servo thread allocated";
  EXPECT_EQ(dev.refused_commands(), 0);            // never a NaN force
  EXPECT_FALSE(servo.period_errors_ns().empty());
}

TEST(ServoThread, StopsPromptlyAndLeavesZeroForce) {
  const SampleField f = plane_field({0, 0, 1}, {0.016, 0.016, 0.010});
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>(f));
  HriParams hp;
  HriRenderer renderer(hp);
  struct Probe final : HapticDeviceIO {
    std::atomic<long> writes{0};
    Vec3 last{1, 1, 1};
    Vec3 read_position_m() override { return {0.016, 0.016, 0.009}; }  // held inside
    void write_force_n(const Vec3& f) override {
      last = f;
      writes.fetch_add(1);
    }
  } probe;
  ServoThreadConfig cfg;
  cfg.rate_hz = 10000;
  ServoThread servo(published, renderer, probe, cfg);
  servo.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto t0 = std::chrono::steady_clock::now();
  servo.stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(200));
  EXPECT_GT(probe.writes.load(), 10);
  EXPECT_EQ(norm(probe.last), 0.0);  // the last command leaves the device unforced
}
