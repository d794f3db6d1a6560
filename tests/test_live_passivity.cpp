// The passivity controller on the servo's live output stage (servo/live_passivity.h), judged
// at the boundary: a test-double device integrates the force it is written (a point mass,
// its own damping, a hand spring pressing it into a wall) on its own clock, one servo
// period per write, and the test reads the simulated device's own energy, not the
// controller's observer. The wall is stiffer than the Colgate-Schenkel bound
// (K = 5000 N/m > 2 b / T = 2000 N/m at 1 kHz, b = 1 N s/m): without the controller it keeps
// oscillating and hands the device energy; with it, it settles.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <thread>

#include "isotouch/servo/servo_thread.h"

using namespace isotouch::core;
using namespace isotouch::servo;

namespace {
constexpr double kPeriodS = 1e-3;  // the servo's and the double's period [s]
constexpr double kWallK = 5000;    // [N/m]
constexpr long kTicks = 1500;      // the double integrates this many writes, then stands still

/// A wall at z = 0 (inside below) with no damping: F = K depth, +z.
class StiffWall final : public Renderer {
 public:
  const char* name() const override { return "stiff wall"; }
  void reset() override {}
  HriTick tick(const FieldView&, const Vec3& hip, double) override {
    HriTick t;
    t.force_n = {0, 0, kWallK * std::max(0.0, -hip.z)};
    t.contact = hip.z < 0;
    return t;
  }
};

/// A point mass (80 g, b = 1 N s/m) pressed into the wall by a hand spring (50 N/m, 1 N
/// pre-load), arriving at 5 cm/s. Each write is held for one period and integrated (20
/// substeps, semi-implicit Euler); the device clock advances one period per write.
class MassOnAWall final : public HapticDeviceIO {
 public:
  Vec3 read_position_m() override { return {0, 0, z_}; }
  DeviceReading read() override {
    DeviceReading r;
    r.position_m = {0, 0, z_};
    r.device_time_us = std::uint32_t(1 + writes_.load(std::memory_order_relaxed) * 1000);
    return r;
  }
  void write_force_n(const Vec3& f) override {
    const long k = writes_.load(std::memory_order_relaxed);
    if (k >= kTicks) return;
    constexpr double m = 0.08, b = 1.0, kh = 50, target = -1.0 / 50;
    const double h = kPeriodS / 20;
    for (int s = 0; s < 20; ++s) {
      const double z0 = z_;
      v_ += h * (f.z + kh * (target - z_) - b * v_) / m;
      z_ += h * v_;
      work_ += f.z * (z_ - z0);        // what the sent force did on the device
      loss_ += b * v_ * (z_ - z0);     // what the device's own damper took out
    }
    max_energy_ = std::max(max_energy_, work_ - loss_);
    if (k >= kTicks / 2) late_lo_ = std::min(late_lo_, z_), late_hi_ = std::max(late_hi_, z_);
    writes_.store(k + 1, std::memory_order_release);
  }
  bool done() const { return writes_.load(std::memory_order_acquire) >= kTicks; }
  /// Largest work of the sent force less the device's damping loss, over the run [J].
  double max_energy_j() const { return max_energy_; }
  /// Half the peak-to-peak of z over the second half of the run [m].
  double late_amplitude_m() const { return 0.5 * (late_hi_ - late_lo_); }

 private:
  std::atomic<long> writes_{0};
  double z_ = 2e-4, v_ = -0.05;
  double work_ = 0, loss_ = 0, max_energy_ = 0;
  double late_lo_ = INFINITY, late_hi_ = -INFINITY;
};

struct Pressed {
  double max_energy_j, late_amplitude_m;
  PassivityStats stats;
};

Pressed press(bool control) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>());
  StiffWall wall;
  MassOnAWall device;
  ServoThreadConfig cfg;
  cfg.rate_hz = 1.0 / kPeriodS;
  cfg.sched_fifo = cfg.pin_cpu = cfg.lock_memory = false;
  cfg.ramp_in_s = 0;  // the double's clock is not the wall clock: no ramp on the wall clock
  cfg.passivity_control = control;
  cfg.passivity_alpha_max_n_s_per_m = 40;  // 0.5 m / T
  ServoThread servo(published, wall, device, cfg);
  servo.start();
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!device.done() && std::chrono::steady_clock::now() < give_up)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  servo.stop();
  EXPECT_TRUE(device.done()) << "the servo wrote fewer than " << kTicks << " forces in 60 s";
  return {device.max_energy_j(), device.late_amplitude_m(), servo.passivity()};
}
}  // namespace

TEST(LivePassivity, KeepsTheDevicesEnergyFromGrowingBehindAStiffWall) {
  const Pressed on = press(true);
  // The wall's stored energy at rest is 0.5 K d^2 = 0.5 J/m x 5000 x (1/5050 m)^2 = 98 uJ:
  // the device's own balance stays below a tenth of it.
  EXPECT_LT(on.max_energy_j, 1e-5);
  EXPECT_LT(on.late_amplitude_m, 1e-4);
  EXPECT_TRUE(on.stats.control);
  EXPECT_TRUE(on.stats.device_clock);
  EXPECT_GT(on.stats.active_ticks, 0);
  EXPECT_GT(on.stats.dissipated_j, 0);
}

TEST(LivePassivity, WithoutTheControllerTheSameWallOscillates) {
  const Pressed off = press(false);
  EXPECT_GT(off.max_energy_j, 1e-3);         // the wall handed the device energy
  EXPECT_GT(off.late_amplitude_m, 5e-4);     // a sustained oscillation over 0.5 mm
  EXPECT_FALSE(off.stats.control);
  EXPECT_EQ(off.stats.active_ticks, 0);
  EXPECT_GT(off.stats.energy_out_j, off.stats.energy_in_j);  // the observer saw the wall active
}

// A backend without a clock (device_time_us 0: an SDK's frame, a link) re-reads its last
// report on the servo's faster ticks: each position below repeats 4 times. The held force
// pushes along the motion (it hands the user energy), so the controller damps; its damping
// must answer the true velocity (4 mm/s), never the 4-fold one a one-period step over a
// 4-period motion would give: at most alpha_max x v on every tick.
TEST(LivePassivity, AReportReadAgainOnTheServosClockDoesNotMultiplyTheDamping) {
  constexpr double alpha_max = 2.0, v = 4e-3, T = 1e-3;
  constexpr int repeats = 4;
  LivePassivity lp;
  lp.start(true, alpha_max, 10.0);
  const Vec3 push{0, 0, 1.0};  // [N] along +z, the motion's direction
  double largest = 0;
  long damped = 0;
  for (int k = 0; k < 400; ++k) {
    const double z = v * T * repeats * double(k / repeats);  // a new report every 4 ticks
    const Vec3 out = lp.step(std::int64_t(k) * 1000000, 0, {0, 0, z}, push);
    const double damping = std::abs(out.z - push.z);
    largest = std::max(largest, damping);
    damped += damping > 0;
    lp.sent(out);
  }
  EXPECT_GT(damped, 10) << "the test's premise: the controller damps";
  EXPECT_LE(largest, alpha_max * v * (1 + 1e-9)) << "damping past alpha_max x the true velocity";
}
