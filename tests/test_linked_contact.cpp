// A wall through a delayed link (sim/delayed_link.h, sim/linked_contact.h): the link's
// timing, and the time-domain passivity controller at the device end, judged by the
// simulated device's own motion and energy.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <utility>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/linked_contact.h"

using namespace isotouch::core;
using namespace isotouch::sim;

namespace {
const Vec3 kP{0.016, 0.016, 0.010};
const Vec3 kUp{0, 0, 1};
SampleField wall() { return plane_field(kUp, kP); }

LinkedContact press_100hz_10ms(bool controller) {
  LinkedContact c;
  c.link.rate_hz = 100;
  c.link.round_trip_delay_s = 0.010;
  c.stiffness_n_per_m = 800;
  c.passivity_controller = controller;
  return c;
}

void print(const char* what, const LinkedContactResult& r) {
  std::printf("%s: contact at %.1f ms, amplitude from +200 ms %.4f mm, late %.4f mm, device net energy %.3g J, "
              "max |F| %.3f N, PC in %.3g J out %.3g J dissipated %.3g J active %ld/%ld ticks\n",
              what, r.contact_time_s * 1e3, r.settled_amplitude_m * 1e3, r.late_amplitude_m * 1e3,
              r.device_energy_out_j, r.max_force_n, r.pc_energy_in_j, r.pc_energy_out_j, r.pc_dissipated_j,
              r.pc_active_ticks, r.ticks);
}
}  // namespace

TEST(DelayLine, ArrivesAfterHalfTheRoundTripInOrderAndHoldsTheLast) {
  LinkParams p;
  p.round_trip_delay_s = 0.010;
  DelayLine<int> line(p, 0);
  line.send(0.000, 1);
  line.send(0.001, 2);
  int held = 0;
  EXPECT_EQ(line.receive(0.0049, held), 0);
  EXPECT_EQ(held, 0);
  EXPECT_EQ(line.receive(0.0050, held), 1);
  EXPECT_EQ(held, 1);
  EXPECT_EQ(line.receive(0.0100, held), 1);
  EXPECT_EQ(held, 2);
  EXPECT_EQ(line.receive(1.0, held), 0);
  EXPECT_EQ(held, 2);  // zero-order hold: nothing new, the last value stays
}

TEST(DelayLine, JitterDelaysWithinItsBoundAndNeverReorders) {
  LinkParams p;
  p.round_trip_delay_s = 0.004;
  p.jitter_s = 0.003;
  DelayLine<int> line(p, 0);
  for (int i = 0; i < 1000; ++i) line.send(i * 1e-3, i);
  int held = -1, last = -1;
  double min_late = 1, max_late = 0;
  for (int k = 0; k < 2000000; ++k) {
    const double t = k * 1e-6;
    if (line.receive(t, held) > 0) {
      EXPECT_GT(held, last);
      last = held;
      const double late = t - held * 1e-3 - 0.002;
      min_late = std::min(min_late, late);
      max_late = std::max(max_late, late);
    }
  }
  EXPECT_EQ(last, 999);
  EXPECT_GE(min_late, -1e-6);
  EXPECT_LE(max_late, 0.003 + 1e-6);
  EXPECT_GT(max_late, 0.002);  // the jitter was drawn, not zero
}

TEST(LinkedContact, WallAt100HzWith10msOscillatesWithoutTheController) {
  const LinkedContact c = press_100hz_10ms(false);
  const LinkedContactResult r = simulate_linked_contact(wall(), kP, kUp, c);
  print("100 Hz, 10 ms, K = 800, no controller", r);
  EXPECT_GT(r.late_amplitude_m, 1e-3);
  EXPECT_FALSE(r.stable(c));
  EXPECT_GT(r.device_energy_out_j, 0.01);
}

TEST(LinkedContact, WallAt100HzWith10msSettlesWithTheController) {
  const LinkedContact c = press_100hz_10ms(true);
  const LinkedContactResult r = simulate_linked_contact(wall(), kP, kUp, c);
  print("100 Hz, 10 ms, K = 800, controller", r);
  EXPECT_FALSE(r.nonfinite);
  EXPECT_GE(r.contact_time_s, 0);
  EXPECT_LT(r.settled_amplitude_m, 1e-4);
  EXPECT_TRUE(r.stable(c));
  EXPECT_LE(r.device_energy_out_j, 0.0);
}

TEST(LinkedContact, WallAt100HzWith10msAndJitterSettlesWithTheController) {
  LinkedContact c = press_100hz_10ms(true);
  c.link.jitter_s = 0.004;  // each message up to 4 ms later still
  const LinkedContactResult r = simulate_linked_contact(wall(), kP, kUp, c);
  print("100 Hz, 10 ms + up to 4 ms jitter, K = 800, controller", r);
  EXPECT_LT(r.settled_amplitude_m, 1e-4);
  EXPECT_LE(r.device_energy_out_j, 0.0);
  c.passivity_controller = false;
  EXPECT_FALSE(simulate_linked_contact(wall(), kP, kUp, c).stable(c));
}

TEST(LinkedContact, SlowPressMeanForceOver100msIsWithinTenPercentOfKDepthWithTheController) {
  LinkedContact c = press_100hz_10ms(true);
  c.motion = LinkedMotion::kSlowPress;
  c.device.hand_stiffness_n_per_m = 300;
  c.device.hand_damping_n_s_per_m = 5;
  c.duration_s = 3.0;
  const LinkedContactResult r = simulate_linked_contact(wall(), kP, kUp, c);
  print("slow press, 100 Hz, 10 ms, controller", r);
  std::printf("stiffness error over 100 ms windows %.4f, per tick %.4f\n", r.max_force_error_ratio, r.max_tick_force_error_ratio);
  EXPECT_GT(r.max_force_n, 1.0);
  EXPECT_LT(r.max_force_error_ratio, 0.10);
}

TEST(LinkedContact, TheHeldForceChangesOnlyWhenAMessageArrivesAtTheLinkRate) {
  LinkedContact c;
  c.link.rate_hz = 100;  // one pose every 10 device ticks; no delay: the answer comes the same tick
  c.motion = LinkedMotion::kSlowPress;
  const LinkedContactResult r = simulate_linked_contact(wall(), kP, kUp, c);
  long changes = 0;
  for (std::size_t k = 1; k < r.force_trace_n.size(); ++k)
    if (r.force_trace_n[k] != r.force_trace_n[k - 1]) {
      ++changes;
      EXPECT_EQ(k % 10, 0u) << "the force changed at device tick " << k;
    }
  EXPECT_GT(changes, 10);
}

// Timing the simulation cannot honour is refused by field and value, not rounded or
// left to undefined behaviour.
TEST(LinkedContact, RejectsLinkAndDeviceTimingItCannotHonour) {
  auto message = [](const LinkedContact& c) {
    try {
      simulate_linked_contact(wall(), kP, kUp, c);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  auto with = [](auto change) {
    LinkedContact c;
    c.duration_s = 0.05;
    change(c);
    return c;
  };
  const std::pair<LinkedContact, const char*> cases[] = {
      {with([](LinkedContact& c) { c.link.rate_hz = 0; }), "rate_hz = 0"},
      {with([](LinkedContact& c) { c.link.rate_hz = -100; }), "rate_hz = -100"},
      {with([](LinkedContact& c) { c.link.rate_hz = NAN; }), "rate_hz = nan"},
      {with([](LinkedContact& c) { c.link.rate_hz = 300; }), "rate_hz = 300"},  // 3.33 device ticks
      {with([](LinkedContact& c) { c.link.round_trip_delay_s = -0.001; }), "round_trip_delay_s = -0.001"},
      {with([](LinkedContact& c) { c.link.jitter_s = -0.002; }), "jitter_s = -0.002"},
      {with([](LinkedContact& c) { c.device_period_s = 0; }), "device_period_s = 0"},
      {with([](LinkedContact& c) { c.device_period_s = -1e-3; }), "device_period_s = -0.001"},
      {with([](LinkedContact& c) { c.pc_alpha_max_n_s_per_m = NAN; }), "alpha_max = nan"},
  };
  for (const auto& [cfg, expected] : cases) EXPECT_NE(message(cfg).find(expected), std::string::npos) << message(cfg);
  EXPECT_EQ(message(with([](LinkedContact& c) { c.link.rate_hz = 250; })), "accepted");  // 4 device ticks
}

// The round trip a pose's force takes through the simulation, for each swept delay: each
// half is served at the device's next 1 ms tick (0.5 ms -> 1 ms, 2.5 ms -> 3 ms), and never
// a tick later from floating-point error in t + one way.
TEST(LinkedContact, RoundTripIsEachHalfRoundedUpToADeviceTick) {
  const std::pair<double, double> delay_and_served_ms[] = {{0, 0}, {1, 2}, {2, 2}, {5, 6}, {10, 10}, {20, 20}};
  for (const auto& [delay_ms, served_ms] : delay_and_served_ms) {
    LinkedContact c;
    c.link.round_trip_delay_s = delay_ms * 1e-3;
    const LinkedContactResult r = simulate_linked_contact(wall(), kP, kUp, c);
    EXPECT_GT(r.round_trips, 1000) << delay_ms << " ms";
    EXPECT_NEAR(r.round_trip_min_s * 1e3, served_ms, 1e-9) << delay_ms << " ms";
    EXPECT_NEAR(r.round_trip_max_s * 1e3, served_ms, 1e-9) << delay_ms << " ms";
  }
}

// The controller's damping cap follows the device: 0.5 m / T unless set.
TEST(LinkedContact, DampingCapIsHalfTheMassOverTheDevicePeriod) {
  LinkedContact c;
  c.device.mass_kg = 0.16;
  c.device_period_s = 2e-3;
  EXPECT_NEAR(c.pc_alpha_max(), 40.0, 1e-12);  // 0.5 * 0.16 kg / 2 ms
  c.device.mass_kg = 0.08;
  c.device_period_s = 1e-3;
  EXPECT_NEAR(c.pc_alpha_max(), 40.0, 1e-12);  // the former fixed value, now derived
  c.device_period_s = 0.5e-3;
  EXPECT_NEAR(c.pc_alpha_max(), 80.0, 1e-12);
  c.pc_alpha_max_n_s_per_m = 12.5;
  EXPECT_EQ(c.pc_alpha_max(), 12.5);
}

// When even the search's lowest K is unstable the answer is 0 (below the search), never
// that lowest K, which a K_max found at the floor would also read.
TEST(LinkedContact, KMaxBelowTheSearchIsZero) {
  const LinkedContact c = press_100hz_10ms(false);  // 800 N/m oscillates here (test above)
  EXPECT_EQ(find_k_max_linked(wall(), kP, kUp, c, 800, 1600, 2), 0.0);
}

// sim::link_k_max: the stiffness check's bound of a link (service/igtl_device.cpp). It is
// the link sweep's search (bench/link_stability.cpp calls it for the wall's table): checked
// here against find_k_max_linked run by hand on the sweep's wall and press, and at no delay
// against Colgate and Schenkel's 2 (b - |B|) / T computed from the press's own device.
namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

TEST(LinkKMax, IsTheSweepsSearchOnItsWallWithoutAndWithTheController) {
  for (const auto& [rate, delay] : {std::pair{100.0, 0.010}, std::pair{250.0, 0.002}}) {
    LinkedContact c;  // the sweep's press: bench/link_stability.cpp press()
    c.link.rate_hz = rate;
    c.link.round_trip_delay_s = delay;
    const double by_hand = find_k_max_linked(wall(), kP, kUp, c, 10, 1e5, 10);
    c.passivity_controller = true;
    const double by_hand_pc = find_k_max_linked(wall(), kP, kUp, c, 10, 1e5, 10);
    const auto t0 = std::chrono::steady_clock::now();
    const LinkBound b = link_k_max(LinkedContact{}, rate, delay);
    std::printf("%g Hz, %g ms: K_max %.1f N/m, with the controller %.1f N/m (by hand %.1f, %.1f); one call %.3f s\n",
                rate, delay * 1e3, b.k_max_n_per_m, b.k_max_with_pc_n_per_m, by_hand, by_hand_pc, seconds_since(t0));
    EXPECT_EQ(b.k_max_n_per_m, by_hand);
    EXPECT_EQ(b.k_max_with_pc_n_per_m, by_hand_pc);
    EXPECT_EQ(b.device_period_s, 1e-3);  // the sweep's device loop, unchanged
    EXPECT_GT(b.k_max_with_pc_n_per_m, b.k_max_n_per_m);
  }
}

TEST(LinkKMax, WithoutDelayAndControllerItIsNearColgateSchenkel) {
  // Colgate and Schenkel's b is the device's own damping to ground (the hand's damping acts
  // through its spring, not in b: with b 0.01 + hand 5 N s/m the simulation's bound is 0.17-0.36
  // of 2 (b + b_hand) / T at 100-1000 Hz, measured, which the stiffness check now uses).
  // Tolerance +-15 %: the bisection's step (10 steps over 10-1e5 N/m: a factor
  // 1e4^(1/1024), 0.9 %), the 1.5 s press judged by its late oscillation (a wall just under
  // the bound decays too slowly to be judged stable: low) and the hand's spring to ground
  // (50 N/m: high). Measured 0.87-1.05.
  for (double rate : {100.0, 250.0, 1000.0})
    for (double b : {1.0, 4.0}) {
      LinkedContact c;
      c.device.damping_n_s_per_m = b;
      const double colgate = 2.0 * b * rate;  // 2 (b - |B|) / T with B = 0
      const LinkBound lb = link_k_max(c, rate, 0);
      std::printf("%g Hz, b %g N s/m: K_max %.1f N/m, Colgate-Schenkel %.1f N/m (%.3f)\n", rate, b, lb.k_max_n_per_m,
                  colgate, lb.k_max_n_per_m / colgate);
      EXPECT_GE(lb.k_max_n_per_m, 0.85 * colgate) << rate << " Hz, b " << b;
      EXPECT_LE(lb.k_max_n_per_m, 1.15 * colgate) << rate << " Hz, b " << b;
    }
}

TEST(LinkKMax, AMeasuredRateIsSimulatedAsItIs) {
  // 99.9 Hz: 10.01 ms, ten device ticks of 1.001 ms; the bound falls with the rate.
  const LinkBound slow = link_k_max(LinkedContact{}, 99.9, 0.01001);
  EXPECT_DOUBLE_EQ(slow.device_period_s, 1.0 / 99.9 / 10);
  EXPECT_DOUBLE_EQ(slow.rate_hz, 99.9);
  const LinkBound fast = link_k_max(LinkedContact{}, 2000, 0);  // faster than 1 kHz: one tick a message
  EXPECT_DOUBLE_EQ(fast.device_period_s, 1.0 / 2000);
  EXPECT_GT(fast.k_max_n_per_m, slow.k_max_n_per_m);
}

TEST(LinkKMax, RefusesARateOrDelayItCannotSimulate) {
  for (double r : {0.0, -5.0, std::nan("")}) {
    try {
      link_k_max(LinkedContact{}, r, 0);
      ADD_FAILURE() << r;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("rate_hz"), std::string::npos) << e.what();
    }
  }
  try {
    link_k_max(LinkedContact{}, 100, -0.001);
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("round_trip_s"), std::string::npos) << e.what();
  }
}
