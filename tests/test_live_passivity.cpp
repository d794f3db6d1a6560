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
#include <functional>
#include <thread>
#include <vector>

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
  lp.start(true, alpha_max, 10.0, T);
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

namespace {
/// A constant demand along +z (the direction the scripted device moves: the held force hands
/// the user energy, so the controller damps); every `fault_every`-th tick a renderer fault.
class Push final : public Renderer {
 public:
  explicit Push(double f_n, long fault_every = 0, long nan_every = 0) : f_(f_n), every_(fault_every), nan_(nan_every) {}
  const char* name() const override { return "push"; }
  void reset() override {}
  HriTick tick(const FieldView&, const Vec3&, double) override {
    HriTick t;
    ++k_;
    t.force_n = {0, 0, nan_ > 0 && k_ % nan_ == 0 ? NAN : f_};
    t.fault = every_ > 0 && k_ % every_ == 0;
    return t;
  }

 private:
  double f_;
  long every_, nan_, k_ = 0;
};

/// What reading n (the n-th read, before the n-th write) reports: position, device clock and
/// connection. The double keeps every force it is written (the boundary the tests judge).
struct Script {
  std::function<double(long)> z_m;              // position along z [m]
  std::function<std::uint32_t(long)> clock_us;  // device clock [us] (0: none)
  std::function<std::uint32_t(long)> connection = [](long) { return 0u; };
};

class ScriptedDevice final : public HapticDeviceIO {
 public:
  ScriptedDevice(Script s, long ticks) : s_(std::move(s)), ticks_(ticks) { sent_.reserve(std::size_t(ticks)); }
  Vec3 read_position_m() override { return {0, 0, s_.z_m(n())}; }
  DeviceReading read() override {
    const long n = this->n();
    DeviceReading r;
    r.position_m = {0, 0, s_.z_m(n)};
    r.device_time_us = s_.clock_us(n);
    r.connection = s_.connection(n);
    return r;
  }
  void write_force_n(const Vec3& f) override {
    const long k = n();
    if (k >= ticks_) return;  // the stop's zero and later writes: not the script's
    sent_.push_back(f);
    writes_.store(k + 1, std::memory_order_release);
  }
  bool done() const { return n() >= ticks_; }
  /// The forces written, one per tick [N] (read after stop()).
  const std::vector<Vec3>& sent() const { return sent_; }
  double z(long n) const { return s_.z_m(n); }

 private:
  long n() const { return writes_.load(std::memory_order_acquire); }
  Script s_;
  long ticks_;
  std::vector<Vec3> sent_;
  std::atomic<long> writes_{0};
};

struct Driven {
  std::vector<Vec3> sent;
  PassivityStats stats;
};

/// Runs the servo (1 kHz, no ramp, control on) on `device` until its script is written.
Driven drive(ScriptedDevice& device, Renderer& renderer, double alpha_max, double force_limit_n = INFINITY) {
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>());
  ServoThreadConfig cfg;
  cfg.rate_hz = 1.0 / kPeriodS;
  cfg.sched_fifo = cfg.pin_cpu = cfg.lock_memory = false;
  cfg.ramp_in_s = 0;
  cfg.passivity_control = true;
  cfg.passivity_alpha_max_n_s_per_m = alpha_max;
  cfg.force_limit_n = force_limit_n;
  ServoThread servo(published, renderer, device, cfg);
  servo.start();
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!device.done() && std::chrono::steady_clock::now() < give_up)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  servo.stop();
  EXPECT_TRUE(device.done()) << "the servo wrote fewer forces than the script in 60 s";
  return {device.sent(), servo.passivity()};
}
}  // namespace

// A device clock faster than the servo, jittered: the reports the 1 kHz servo reads are
// alternately 0.25 ms and 1.75 ms apart on the device's clock (it moves at 4 mm/s on that
// clock). Each damping force is held for one servo period, so its gain per metre of motion
// may not pass alpha_max / T (the device's limit); a cap over the 0.25 ms step would be 4x it.
TEST(LivePassivity, TheDampingCapIsTakenOverTheHoldPeriodNotAShorterClockStep) {
  constexpr double alpha_max = 2.0, v = 4e-3;
  constexpr long ticks = 400;
  auto clock_us = [](long n) { return std::uint32_t(1 + 2000 * (n / 2) + (n % 2) * 250); };
  ScriptedDevice device({[&](long n) { return v * double(clock_us(n)) * 1e-6; }, clock_us}, ticks);
  Push push(1.0);
  const Driven d = drive(device, push, alpha_max);
  long damped = 0;
  for (long n = 1; n < ticks; ++n) {
    const double damping = 1.0 - d.sent[std::size_t(n)].z, dx = device.z(n) - device.z(n - 1);
    damped += damping > 0;
    ASSERT_LE(damping, alpha_max * dx / kPeriodS * (1 + 1e-9) + 1e-15)
        << "tick " << n << ": damping " << damping << " N for " << dx << " m held for " << kPeriodS << " s";
  }
  EXPECT_GT(damped, 100) << "the test's premise: the controller damps";
}

// A device reset mid-run reports its clock as 0 from then on. The observer restarts on the
// servo's clock (counted) and the controller keeps damping: the device still receives less
// than the 1 N pushed along its motion. (A clock frozen at the reset had no period: no damping.)
// The clock ran 51 ms short of its wrap: read modulo 2^32 the step to 0 is no jump.
TEST(LivePassivity, ADeviceClockResetToZeroRestartsTheObserverAndTheDampingGoesOn) {
  constexpr long ticks = 400, reset_at = 100;
  auto z = [](long n) { return 4e-6 * double(n); };  // 4 mm/s at 1 kHz
  auto clock = [](long n) { return n < reset_at ? std::uint32_t(0xFFFFFFFFu - 150000u + std::uint32_t(1000 * n)) : 0u; };
  ScriptedDevice device({z, clock}, ticks);
  Push push(1.0);
  const Driven d = drive(device, push, 2.0);
  long damped = 0;
  for (long n = reset_at + 10; n < ticks; ++n) damped += d.sent[std::size_t(n)].z < 1.0;
  EXPECT_GT(damped, (ticks - reset_at - 10) * 9 / 10) << "ticks damped after the device's clock reset";
  EXPECT_EQ(d.stats.restarts, 1);
  EXPECT_FALSE(d.stats.device_clock) << "the servo's clock took over";
}

// A clock that goes back (a device restarted counting from a small value) or jumps ahead of
// the servo's by seconds, and a reconnection: each restarts the observer once, and the
// books stay finite (a backward step read modulo 2^32 is a 71-minute period).
TEST(LivePassivity, ABackwardOrJumpingClockAndAReconnectionEachRestartTheObserver) {
  constexpr long ticks = 400;
  auto clock = [](long n) {
    if (n < 100) return std::uint32_t(500000 + 1000 * n);  // then back to 5 us
    if (n < 200) return std::uint32_t(5 + 1000 * (n - 100));
    return std::uint32_t(10000000 + 1000 * n);  // a 10 s jump at tick 200
  };
  ScriptedDevice device({[](long n) { return 4e-6 * double(n); }, clock,
                         [](long n) { return n < 300 ? 0u : 1u; }}, ticks);
  Push push(1.0);
  const Driven d = drive(device, push, 2.0);
  EXPECT_EQ(d.stats.restarts, 3);
  EXPECT_TRUE(d.stats.device_clock);
  EXPECT_TRUE(std::isfinite(d.stats.energy_out_j) && std::isfinite(d.stats.dissipated_j));
  long damped = 0;
  for (long n = 310; n < ticks; ++n) damped += d.sent[std::size_t(n)].z < 1.0;
  EXPECT_GT(damped, 80) << "the controller damps after the last restart";
}

// Ticks that bypass the controller (a renderer fault every 7th tick, a NaN force every
// 11th: the servo sends zero) still held the last force while the device moved. The
// observer's net energy out must equal the work of the forces the device received over the
// motion it made, sum F(n) . (x(n+1) - x(n)), worked out by the test from the double's record.
TEST(LivePassivity, TicksThatSkipTheStageKeepTheBooksWhole) {
  constexpr long ticks = 600;
  auto z = [](long n) { return 1e-3 * std::sin(0.05 * double(n)); };
  ScriptedDevice device({z, [](long n) { return std::uint32_t(1 + 1000 * n); }}, ticks);
  Push push(1.0, 7, 11);
  const Driven d = drive(device, push, 2.0);
  double work = 0, scale = 0;
  for (long n = 0; n < ticks; ++n) {
    const double w = d.sent[std::size_t(n)].z * (z(n + 1) - z(n));
    work += w, scale += std::abs(w);
  }
  ASSERT_GT(scale, 1e-4) << "the test's premise: the forces did work";
  EXPECT_NEAR(d.stats.energy_out_j - d.stats.energy_in_j, work, 1e-9 * scale);
}

// The controller on, a 0.3 N force limit and a stiff wall that asks for up to 5 N: every
// force the device receives is finite and within the limit, whatever the damping adds.
TEST(LivePassivity, TheGateClampsTheDampedForceToASmallLimit) {
  const double limit = 0.3;
  TripleBuffer<SampleField> published;
  published.publish(std::make_shared<const SampleField>());
  StiffWall wall;
  ScriptedDevice device({[](long n) { return 1e-3 * std::sin(0.2 * double(n)) - 5e-4; },
                         [](long n) { return std::uint32_t(1 + 1000 * n); }}, 800);
  const Driven d = drive(device, wall, 40.0, limit);
  double largest = 0;
  long nonfinite = 0;
  for (const Vec3& f : d.sent) {
    nonfinite += !std::isfinite(f.x) || !std::isfinite(f.y) || !std::isfinite(f.z);
    largest = std::max(largest, std::sqrt(f.x * f.x + f.y * f.y + f.z * f.z));
  }
  EXPECT_EQ(nonfinite, 0);
  EXPECT_LE(largest, limit * (1 + 1e-12));
  EXPECT_GT(largest, 0.9 * limit) << "the test's premise: the wall pushes at the limit";
  EXPECT_GT(d.stats.active_ticks, 0) << "the test's premise: the controller damps";
}

// The line the sculpting app's stats panel and its --stats print show: hand-written values.
TEST(LivePassivity, DescribeSaysWhatTheObserverMeasuredInMillijoules) {
  isotouch::servo::PassivityStats s;
  s.control = true;
  s.device_clock = true;
  s.energy_in_j = 0.0123;
  s.energy_out_j = 0.00456;
  s.dissipated_j = 0.000789;
  s.active_ticks = 12;
  s.restarts = 1;
  EXPECT_EQ(isotouch::servo::describe(s), "controller on (device clock): in 12.3 mJ, out 4.56 mJ, dissipated 0.789 mJ; "
                                          "damping added on 12 ticks, 1 restarts");
  s.control = false;
  s.device_clock = false;
  EXPECT_EQ(isotouch::servo::describe(s).substr(0, 29), "observer only (servo clock): ");
}
