// HRI robust variant following edits on analytic fields, servo only.
//
// An "edit" is a second published field (SampleField::version + 1) with the surface moved
// in (carve) or out (add). Truth comes from the analytic shapes (sim/analytic_fields.h:
// half-space and sphere, value = 1000 * signed distance [mm], gradient analytic, positive
// inside, tau = 0) and from the spring law F = K * depth: never from the renderer's own
// output. The rule under test: the force step an edit causes is eased out linearly over
// edit_period_s (10 ticks here), the time the edit's material took to remove; in these
// shapes every such step is at most 1.65 N, so no tick changes |F| by more than 5 % of the
// limit. Each test also runs the renderer with the feature off (edit_period_s = 0) where
// that shows the fault the feature removes, so a test that cannot fail is caught.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/core/brick_field.h"
#include "isotouch/servo/hri.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

namespace {

constexpr double kVoxel = 1e-3;  // voxel [m] of every field here
constexpr double kK = 800.0;     // stiffness [N/m]
constexpr double kLimit = 3.3;   // force limit [N]
constexpr double kPeriod = 0.01;  // edit_period_s: an edit's force step eases out over it [s]
constexpr int kEase = 10;         // ... that is 10 ticks at 1 kHz
constexpr double kStep = 0.05 * kLimit;  // 5 % of the limit: above every eased step here [N]
constexpr double kX = 0.016, kY = 0.016;  // the probe's x, y [m] (centre of the 32 mm box)

HriParams params(double period_s = kPeriod, int n = 5) {
  HriParams p;
  p.tau = 0;
  p.stiffness_n_per_m = kK;
  p.damping_n_s_per_m = 1.0;
  p.plane_update_period = n;
  p.rate_hz = 1000;
  p.force_limit_n = kLimit;
  p.edit_period_s = period_s;
  return p;
}

/// Floor: inside below z = z0_m [m] (outward normal +z), published as `version`.
SampleField floor_at(double z0_m, std::uint64_t version) {
  SampleField f = plane_field({0, 0, 1}, {kX, kY, z0_m});
  f.version = version;
  return f;
}

/// Solid sphere of radius r_m [m] around c, published as `version`.
SampleField ball(const Vec3& c, double r_m, std::uint64_t version) {
  SampleField f = sphere_field(c, r_m, 40);
  f.version = version;
  return f;
}

using FieldAt = std::function<const SampleField&(int)>;
using HipAt = std::function<Vec3(int)>;

/// Ticks 0..n-1 at the nominal period: tick k reads field_at(k) with the HIP at hip_at(k).
std::vector<HriTick> drive(HriRenderer& r, int n, const FieldAt& field_at, const HipAt& hip_at) {
  std::vector<HriTick> out;
  out.reserve(std::size_t(n));
  for (int k = 0; k < n; ++k) out.push_back(r.tick(field_at(k), hip_at(k)));
  return out;
}

/// Largest | |F_k| - |F_k-1| | over the run (|F| before the first tick: 0) [N], and its tick.
double max_step(const std::vector<HriTick>& t, int* at = nullptr) {
  double worst = 0, prev = 0;
  for (std::size_t k = 0; k < t.size(); ++k) {
    const double m = norm(t[k].force_n);
    if (std::abs(m - prev) > worst) {
      worst = std::abs(m - prev);
      if (at) *at = int(k);
    }
    prev = m;
  }
  return worst;
}

/// Largest |F_k - F_k-1| (vector) over ticks [from, to) [N].
double max_vector_step(const std::vector<HriTick>& t, int from, int to) {
  double worst = 0;
  for (int k = std::max(from, 1); k < to; ++k) worst = std::max(worst, norm(t[k].force_n - t[k - 1].force_n));
  return worst;
}

/// A HIP that comes down from z = 18 mm at 50 um per tick to z_hold and stays there.
HipAt press_to(double z_hold) {
  return [z_hold](int k) { return Vec3{kX, kY, std::max(z_hold, 0.018 - 5e-5 * k)}; };
}

/// Field `a` before tick `edit`, `b` from it on.
FieldAt switch_at(const SampleField& a, const SampleField& b, int edit) {
  return [&a, &b, edit](int k) -> const SampleField& { return k < edit ? a : b; };
}

}  // namespace

// Carve under the VHIP: the floor is lowered by 1 mm under a HIP held 2.5 mm deep. The
// VHIP goes to the new floor on the edit tick and |F| eases from K * 2.5 mm = 2.0 N to
// K * 1.5 mm = 1.2 N linearly over the edit period (0.08 N per tick).
TEST(HriEdit, CarveUnderTheVhipEasesTheForceDownToTheNewDepth) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.015, 2);
  const int edit = 152, ticks = 300;  // 152: mid-period for n = 5 (checked below)
  const HipAt hip = press_to(0.0135);
  HriRenderer on(params()), off(params(0));
  const auto t = drive(on, ticks, switch_at(before, after, edit), hip);
  const auto t0 = drive(off, ticks, switch_at(before, after, edit), hip);

  // The bound, over the whole run (approach, hold, edit, settle), and the direction: +z.
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_LE(max_vector_step(t, 1, ticks), kStep * (1 + 1e-12));
  // Without the feature the same edit steps by 0.8 N at once (the test can fail).
  EXPECT_GT(max_step(t0), 3 * kStep);

  // Before the edit: K * 2.5 mm.
  EXPECT_NEAR(norm(t[edit - 1].force_n), kK * 0.0025, 1e-5);
  // Re-evaluated on the edit tick (the feature-off run shows the tick is not an n-tick
  // update), the VHIP already on the new floor.
  EXPECT_TRUE(t[edit].plane_update);
  EXPECT_FALSE(t0[edit].plane_update);
  EXPECT_NEAR(t[edit].plane.p.z, 0.015, 1e-3 * kVoxel);
  // |F| goes down linearly over the edit period, the proxy shown on the receding floor.
  for (int j = 0; j < kEase; ++j) {
    const double s = 1.0 - (j + 1.0) / kEase;
    EXPECT_NEAR(norm(t[edit + j].force_n), kK * (0.0015 + 0.001 * s), 1e-5) << j;
    EXPECT_NEAR(t[edit + j].vhip_m.z, 0.015 + 0.001 * s, 1e-3 * kVoxel) << j;
    EXPECT_TRUE(t[edit + j].contact) << j;
  }
  // Settled: VHIP on the new surface (analytic distance), F = K * new depth along +z.
  const HriTick& last = t.back();
  EXPECT_TRUE(last.contact);
  EXPECT_NEAR(last.vhip_m.z, 0.015, 1e-3 * kVoxel);
  EXPECT_NEAR(last.force_n.z, kK * 0.0015, 1e-5);
  EXPECT_NEAR(norm(last.force_n), kK * 0.0015, 1e-5);
  for (int k = edit + kEase - 1; k < ticks; ++k) EXPECT_NEAR(norm(t[k].force_n), kK * 0.0015, 1e-5) << k;
}

// The ease cannot push |F| past the limit: the floor is carved 1 mm (16 -> 15 mm) under a
// HIP held 3.5 mm deep (K * 3.5 mm = 2.8 N), so the ease's offset is K * 1 mm = 0.8 N along
// +z; from the next tick the user presses on, 0.5 mm per tick for 4 ticks (HIP 12.5 ->
// 10.5 mm). On the first pressed tick the target (K * 3 mm = 2.4 N plus the press's damping)
// is still under the limit, but target + what is left of the offset (8/10 of 0.8 N) is not;
// on the later ticks the target is at the limit itself and the offset comes on top. The
// ease's own saturation must hold |F| at the limit on every one of those ticks (saturating
// at twice the limit instead sent up to 3.78 N).
TEST(HriEdit, TheEasedForceNeverExceedsTheLimitWhenTheUserPressesOn) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.015, 2);
  const int edit = 152, ticks = 260;
  const HipAt hip = [edit](int k) {
    const double held = std::max(0.0125, 0.018 - 5e-5 * k);  // 3.5 mm into the old floor by tick 110
    return Vec3{kX, kY, held - 5e-4 * std::clamp(k - edit, 0, 4)};
  };
  HriRenderer r(params());
  const auto t = drive(r, ticks, switch_at(before, after, edit), hip);

  EXPECT_NEAR(norm(t[edit - 1].force_n), kK * 0.0035, 1e-5);  // 2.8 N before the edit
  // The edit tick, HIP still: the target K * 2.5 mm = 2.0 N plus 9/10 of the 0.8 N offset.
  EXPECT_NEAR(norm(t[edit].force_n), kK * 0.0025 + 0.9 * kK * 0.001, 1e-5);
  EXPECT_FALSE(t[edit].saturated);
  // Pressed during the ease: target + offset over the limit, sent at the limit along +z.
  for (int k = edit + 1; k < edit + kEase; ++k) {
    EXPECT_TRUE(t[k].saturated) << "tick " << k;
    EXPECT_NEAR(norm(t[k].force_n), kLimit, 1e-9) << "tick " << k;
    EXPECT_NEAR(t[k].force_n.z, kLimit, 1e-9) << "tick " << k;  // along the floor's normal
  }
  for (int k = 0; k < ticks; ++k) EXPECT_LE(norm(t[k].force_n), kLimit * (1 + 1e-12)) << "tick " << k;
}

// Carve deeper than the HIP: the floor goes from z = 16 mm to 12 mm under a HIP held at
// 14 mm (1.6 N). The HIP is now in the air: |F| eases to 0 over the edit period (along +z,
// never a pull; the proxy shown on the receding floor, in contact), then stays 0.
TEST(HriEdit, CarveDeeperThanTheHipFadesTheForceOut) {
  const SampleField before = floor_at(0.016, 4), after = floor_at(0.012, 5);
  const int edit = 153, ticks = 260;
  const HipAt hip = press_to(0.014);
  HriRenderer on(params()), off(params(0));
  const auto t = drive(on, ticks, switch_at(before, after, edit), hip);
  const auto t0 = drive(off, ticks, switch_at(before, after, edit), hip);

  EXPECT_NEAR(norm(t[edit - 1].force_n), kK * 0.002, 1e-5);
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_GT(max_step(t0), 5 * kStep);  // feature off: 1.6 N -> 0 in one tick
  // Fading: |F| falls by a tenth of 1.6 N per tick (nothing else changes) along +z.
  const int fade = kEase;  // ticks to reach 0
  for (int k = edit; k < edit + fade; ++k) {
    const double m = norm(t[k].force_n);
    EXPECT_NEAR(m, kK * 0.002 * (1.0 - (k - edit + 1.0) / kEase), 1e-9) << k;
    if (m > 1e-9) {
      EXPECT_NEAR(t[k].force_n.z, m, 1e-12) << k;  // pushes out, no sideways part
      EXPECT_TRUE(t[k].contact) << k;
      EXPECT_NEAR(t[k].vhip_m.z, 0.014 + m / kK, 1e-9) << k;  // on the floor as it recedes
      EXPECT_NEAR(t[k].penetration_m, m / kK, 1e-9) << k;
    }
    EXPECT_FALSE(t[k].fault) << k;
  }
  for (int k = edit + fade; k < ticks; ++k) {
    EXPECT_EQ(norm(t[k].force_n), 0.0) << k;
    EXPECT_FALSE(t[k].contact) << k;
    EXPECT_NEAR(t[k].vhip_m.z, 0.014, 1e-12) << k;  // free motion: VHIP = HIP
  }
}

// Carve deeper than the HIP with the HIP moving slowly down (5 um per tick): the force fades
// out, then the HIP reaches the new floor and feels it, the bound holding all the way; at the
// end F = K * depth + B * v along +z.
TEST(HriEdit, CarveDeeperThanAMovingHipFadesThenTheNewFloorHolds) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.012, 2);
  const int edit = 400, ticks = 1200;
  const double v = 5e-3;  // HIP speed [m/s] (5 um per 1 ms tick)
  const HipAt hip = [v](int k) { return Vec3{kX, kY, 0.017 - v * 1e-3 * k}; };
  HriRenderer on(params());
  const auto t = drive(on, ticks, switch_at(before, after, edit), hip);
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_GT(norm(t[edit - 1].force_n), 0.7);           // 1 mm deep before the edit
  EXPECT_EQ(norm(t[edit + 20].force_n), 0.0);          // faded, in the air
  const double z_end = hip(ticks - 1).z, depth = 0.012 - z_end;
  ASSERT_GT(depth, 0.0009);
  EXPECT_NEAR(t.back().vhip_m.z, 0.012, 1e-3 * kVoxel);
  EXPECT_NEAR(t.back().force_n.z, kK * depth + 1.0 * v, 1e-4);
}

// Add over the VHIP: the floor rises from 16 mm to 17.5 mm over a HIP held at 15 mm. The
// proxy is brought out to the new floor and |F| rises from 0.8 N to K * 2.5 mm = 2.0 N
// linearly over the edit period.
TEST(HriEdit, AddOverTheVhipBringsTheProxyOutGradually) {
  const SampleField before = floor_at(0.016, 9), after = floor_at(0.0175, 10);
  const int edit = 153, ticks = 300;  // 153: mid-period for n = 5 (checked below)
  const HipAt hip = press_to(0.015);
  HriRenderer on(params()), off(params(0));
  const auto t = drive(on, ticks, switch_at(before, after, edit), hip);
  const auto t0 = drive(off, ticks, switch_at(before, after, edit), hip);

  EXPECT_NEAR(norm(t[edit - 1].force_n), kK * 0.001, 1e-5);
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_LE(max_vector_step(t, 1, ticks), kStep * (1 + 1e-12));
  EXPECT_GT(max_step(t0), 5 * kStep);  // feature off: 0.8 N -> 2.0 N at the next update
  EXPECT_TRUE(t[edit].plane_update);
  EXPECT_FALSE(t0[edit].plane_update);
  EXPECT_NEAR(t[edit].plane.p.z, 0.0175, 1e-3 * kVoxel);  // out on the edit tick
  for (int j = 0; j < kEase; ++j)
    EXPECT_NEAR(norm(t[edit + j].force_n), kK * (0.0025 - 0.0015 * (1.0 - (j + 1.0) / kEase)), 1e-5) << j;
  for (int k = edit + kEase - 1; k < ticks; ++k) EXPECT_NEAR(norm(t[k].force_n), kK * 0.0025, 1e-5) << k;
  EXPECT_NEAR(t.back().vhip_m.z, 0.0175, 1e-3 * kVoxel);
  EXPECT_NEAR(t.back().force_n.z, kK * 0.0025, 1e-5);
}

// A thick addition (the floor rises by 10 mm over a HIP 1 mm deep, beyond the 8-voxel reach
// of the bounded embedded-VHIP search): the proxy is still brought out to the new floor,
// and |F| rises to the saturated K * 11 mm (8.8 N -> the 3.3 N limit) over the edit period:
// 2.5 N in 10 ticks (the ease's rate is the edit's own, 250 N/s here).
TEST(HriEdit, AThickAdditionBringsTheProxyOutToo) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.026, 2);
  const int edit = 153, ticks = 260;
  HriRenderer r(params());
  const auto t = drive(r, ticks, switch_at(before, after, edit), press_to(0.015));
  EXPECT_TRUE(t[edit].plane_update);
  EXPECT_NEAR(t[edit].plane.p.z, 0.026, 1e-3 * kVoxel);
  const double eased = (kLimit - kK * 0.001) / kEase;  // per tick [N]
  EXPECT_LE(max_step(t), eased * (1 + 1e-9));
  EXPECT_NEAR(norm(t[edit].force_n), kK * 0.001 + eased, 1e-5);
  EXPECT_NEAR(r.edit_ease_max_rate(), (kLimit - kK * 0.001) / kPeriod, 1e-6);
  EXPECT_NEAR(t.back().vhip_m.z, 0.026, 1e-3 * kVoxel);
  EXPECT_NEAR(t.back().force_n.z, kLimit, 1e-9);
  EXPECT_TRUE(t.back().saturated);
}

// Material added over a hovering probe (free motion, 0.5 mm above the floor; the floor
// rises by 1.5 mm): the proxy is the HIP of the tick before, outside in the old snapshot,
// so it is brought out to the new surface and |F| rises to K * 1 mm. Without the feature
// the value of the VHIP cached from the old snapshot makes a plane at once: 0.8 N in one tick.
TEST(HriEdit, AddOverAHoveringProbePushesItOutGradually) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.0175, 2);
  const int edit = 100, ticks = 200;
  const HipAt hip = press_to(0.0165);
  HriRenderer on(params()), off(params(0));
  const auto t = drive(on, ticks, switch_at(before, after, edit), hip);
  const auto t0 = drive(off, ticks, switch_at(before, after, edit), hip);

  EXPECT_FALSE(t[edit - 1].contact);
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_TRUE(t[edit].plane_update);
  EXPECT_NEAR(norm(t[edit].force_n), kK * 0.001 / kEase, 1e-5);  // a tenth, not K * 1 mm at once
  for (int k = edit + 10; k < ticks; ++k) {
    EXPECT_NEAR(t[k].force_n.z, kK * 0.001, 1e-5) << k;
    EXPECT_NEAR(t[k].vhip_m.z, 0.0175, 1e-3 * kVoxel) << k;
  }
  EXPECT_GT(max_step(t0), 3 * kStep);  // feature off
}

// The plane is re-evaluated on the edit tick whatever the update period (n = 20), for a
// carve and an add, at every phase of the n-tick counter.
TEST(HriEdit, ThePlaneIsReEvaluatedOnTheEditTick) {
  for (double z_new : {0.015, 0.0165})
    for (int edit = 140; edit < 160; ++edit) {
      const SampleField before = floor_at(0.016, 3), after = floor_at(z_new, 4);
      HriRenderer r(params(kPeriod, 20));
      const auto t = drive(r, edit + 1, switch_at(before, after, edit), press_to(0.0145));
      EXPECT_TRUE(t[edit].plane_update) << "edit at " << edit << ", floor " << z_new;
      EXPECT_NEAR(t[edit].plane.p.z, z_new, 1e-3 * kVoxel);
    }
}

// A curved surface and a sliding HIP: a ball of radius 10 mm grows to 11 mm (add) and then
// shrinks to 9.5 mm (carve) while the HIP slides over its top 1 mm deep at 10 mm/s. Every
// tick's |F| change stays within the bound; at the end the VHIP lies on the final sphere
// (within the trilinear interpolation error of a sampled distance, 3 h^2 / (8 r) per the
// cell's second derivative bound 1/r, doubled for safety) and |F| = K * depth below it.
TEST(HriEdit, EditsUnderASlidingHipOnASphereKeepTheBound) {
  const Vec3 c{0.020, 0.020, 0.018};
  const SampleField b0 = ball(c, 0.010, 1), b1 = ball(c, 0.011, 2), b2 = ball(c, 0.0095, 3);
  const int add = 300, carve = 600, ticks = 1000;
  // The HIP: down onto the top, then along x at 10 um per tick, 1 mm below the first
  // sphere (radius 9 mm around c).
  const double z_start = std::sqrt(0.009 * 0.009 - 0.004 * 0.004);
  const HipAt hip = [&](int k) {
    if (k < 100) return c + Vec3{-0.004, 0, z_start + 0.003 * (1.0 - k / 100.0)};
    const double x = -0.004 + 1e-5 * (k - 100), zr = std::sqrt(0.009 * 0.009 - x * x);
    return c + Vec3{x, 0, zr};
  };
  const FieldAt field = [&](int k) -> const SampleField& { return k < add ? b0 : (k < carve ? b1 : b2); };
  HriRenderer on(params()), off(params(0));
  const auto t = drive(on, ticks, field, hip);
  const auto t0 = drive(off, ticks, field, hip);
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_GT(max_step(t0), 3 * kStep);  // the same run without the feature steps
  EXPECT_TRUE(t[add].plane_update);
  EXPECT_TRUE(t[carve].plane_update);
  for (int k = 0; k < ticks; ++k) EXPECT_FALSE(t[k].fault) << k;
  const double tol = 2 * 3 * kVoxel * kVoxel / (8 * 0.0085);  // [m]
  const double r_vhip = norm(t.back().vhip_m - c);
  EXPECT_NEAR(r_vhip, 0.0095, tol);
  EXPECT_NEAR(norm(t.back().force_n), kK * (0.0095 - 0.009), kK * tol + 0.01);  // + B v_d of sliding
  EXPECT_TRUE(t.back().contact);
}

// Two edits in a row (an add, then a carve 3 ticks later, mid-ease): the second ease starts
// from the |F| sent, and the bound holds; the force ends at K * the final depth.
TEST(HriEdit, AnEditDuringTheEaseRestartsItFromTheForceSent) {
  const SampleField f0 = floor_at(0.016, 1), f1 = floor_at(0.0175, 2), f2 = floor_at(0.0145, 3);
  const int e1 = 150, e2 = 153, ticks = 260;
  const FieldAt field = [&](int k) -> const SampleField& { return k < e1 ? f0 : (k < e2 ? f1 : f2); };
  HriRenderer on(params()), off(params(0));
  const auto t = drive(on, ticks, field, press_to(0.0135));
  const auto t0 = drive(off, ticks, field, press_to(0.0135));
  int worst_at = -1;
  EXPECT_LE(max_step(t, &worst_at), kStep * (1 + 1e-12)) << "at tick " << worst_at;
  EXPECT_GT(max_step(t0), 3 * kStep);
  // Up by a tenth of 1.2 N per tick for 3 ticks, then from there down toward K * 1 mm.
  const double f_before = kK * 0.0025, up = kK * 0.0015 / kEase;
  for (int k = e1; k < e2; ++k) EXPECT_NEAR(norm(t[k].force_n), f_before + (k - e1 + 1) * up, 1e-5) << k;
  const double sent = f_before + 3 * up, f_end = kK * 0.001;
  EXPECT_NEAR(norm(t[e2].force_n), f_end + (sent - f_end) * (1.0 - 1.0 / kEase), 1e-5);
  EXPECT_NEAR(norm(t.back().force_n), kK * 0.001, 1e-5);
  EXPECT_NEAR(t.back().vhip_m.z, 0.0145, 1e-3 * kVoxel);
}

// An edit that also changes the value scale (added material 10 times less steep than the
// old one, same isosurface): the embedded VHIP's depth is estimated from the new snapshot's
// gradient, so the search reaches the new surface (the old |grad| would put it ten times
// too near and leave the VHIP embedded).
TEST(HriEdit, AddWithAnotherGradientScaleStillFindsTheNewSurface) {
  SampleField before = floor_at(0.016, 1);
  for (Sample& v : before.samples) v = {10 * v.value, 10 * v.gx, 10 * v.gy, 10 * v.gz};
  const SampleField after = floor_at(0.0175, 2);
  const int edit = 153, ticks = 260;
  HriRenderer r(params());
  const auto t = drive(r, ticks, switch_at(before, after, edit), press_to(0.015));
  EXPECT_TRUE(t[edit].plane_update);
  EXPECT_NEAR(t[edit].plane.p.z, 0.0175, 1e-3 * kVoxel);
  EXPECT_NEAR(t.back().vhip_m.z, 0.0175, 1e-3 * kVoxel);
  EXPECT_NEAR(norm(t.back().force_n), kK * 0.0025, 1e-5);
  EXPECT_LE(max_step(t), kStep * (1 + 1e-12));
}

// With recovery time on (50 ms), the edit tick starts no recovery ramp: the ease alone
// governs, so the carve reaches K * the new depth after the 10 ms edit period (a 50 ms ramp
// would still be 80 % short of it).
TEST(HriEdit, OnAnEditTickTheEaseReplacesTheRecoveryRamp) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.015, 2);
  const int edit = 152, ticks = 170;
  HriParams p = params();
  p.recovery_time_s = 0.05;
  HriRenderer r(p);
  const auto t = drive(r, ticks, switch_at(before, after, edit), press_to(0.0135));
  EXPECT_NEAR(norm(t[edit - 1].force_n), kK * 0.0025, 1e-5);
  EXPECT_LE(max_step(t), kStep * (1 + 1e-12));
  for (int k = edit + kEase - 1; k < ticks; ++k) EXPECT_NEAR(norm(t[k].force_n), kK * 0.0015, 1e-5) << k;
}

// An edit in the middle of a running recovery ramp (the HIP entered 3 mm in one tick, a
// 50 ms ramp from 0 started, the carve comes 20 ms later): the ease takes the ramp over, so
// |F| reaches K * the new depth within the edit period instead of ramping on for 30 ms.
TEST(HriEdit, AnEditDuringARecoveryRampFoldsTheRampIntoTheEase) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.015, 2);
  const int edit = 21, ticks = 80;
  HriParams p = params();
  p.recovery_time_s = 0.05;
  HriRenderer r(p);
  const HipAt hip = [](int k) { return Vec3{kX, kY, k == 0 ? 0.0165 : 0.0135}; };
  const auto t = drive(r, ticks, switch_at(before, after, edit), hip);
  const double sent = norm(t[edit - 1].force_n);
  ASSERT_LT(sent, kK * 0.0025 * 0.7);  // still ramping up when the edit comes
  const int reach = kEase - 1;
  double worst = 0;
  for (int k = edit; k < ticks; ++k) worst = std::max(worst, std::abs(norm(t[k].force_n) - norm(t[k - 1].force_n)));
  EXPECT_LE(worst, kStep * (1 + 1e-12));
  for (int k = edit + reach; k < ticks; ++k) EXPECT_NEAR(norm(t[k].force_n), kK * 0.0015, 1e-5) << k;
}

// The ease ends after the edit period: after a carve has settled, the user's own quick
// press (0.4 mm per tick, 0.32 N per tick, more than 5 % of the limit) is felt at once,
// F = K * depth on every tick (no damping here).
TEST(HriEdit, AfterTheEaseTheUsersOwnMotionIsNotEased) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.015, 2);
  const int edit = 152, press = 200, ticks = 206;
  HriParams p = params();
  p.damping_n_s_per_m = 0;
  HriRenderer r(p);
  const HipAt hip = [&](int k) {
    const HipAt hold = press_to(0.0135);
    return k < press ? hold(k) : Vec3{kX, kY, 0.0135 - 4e-4 * (k - press + 1)};
  };
  const auto t = drive(r, ticks, switch_at(before, after, edit), hip);
  EXPECT_NEAR(norm(t[press - 1].force_n), kK * 0.0015, 1e-5);  // settled after the carve
  for (int k = press; k < ticks; ++k) {
    EXPECT_NEAR(t[k].force_n.z, kK * (0.015 - hip(k).z), 1e-5) << k;
    EXPECT_GT(norm(t[k].force_n) - norm(t[k - 1].force_n), 1.5 * kStep) << k;
  }
}

// The live edit pipeline publishes bricked snapshots: the version reaches the renderer
// through a bricked FieldView the same way. Carve and add on fp32 bricks converted from the
// analytic floors: the edit tick re-evaluated (the carve leaves the VHIP in a uniform brick
// whose tile is the isovalue itself, 0: the linear rule would keep p at the VHIP), the bound
// held, and the trace of the dense fields within 1e-3 voxel (a HIP deep in a uniform brick
// reads its tile, not the distance, so the linear rule's p differs by a rounding).
TEST(HriEdit, BrickedSnapshotsFollowTheEditLikeDenseOnes) {
  auto bricked = [](const SampleField& dense) {
    SampleField b = make_bricked_field(bricked_input_from_dense(dense, Isosurface{0.0, InsideIs::kAbove}),
                                       SampleFormat::kFp32);
    b.version = dense.version;
    return b;
  };
  for (double z_new : {0.015, 0.0175}) {
    const SampleField d0 = floor_at(0.016, 1), d1 = floor_at(z_new, 2);
    const SampleField b0 = bricked(d0), b1 = bricked(d1);
    ASSERT_TRUE(b1.bricked());
    const int edit = 152, ticks = 220;
    HriRenderer rd(params()), rb(params());
    const auto td = drive(rd, ticks, switch_at(d0, d1, edit), press_to(0.0145));
    const auto tb = drive(rb, ticks, switch_at(b0, b1, edit), press_to(0.0145));
    EXPECT_TRUE(tb[edit].plane_update);
    EXPECT_NEAR(tb[edit].plane.p.z, z_new, 1e-3 * kVoxel);
    EXPECT_LE(max_step(tb), kStep * (1 + 1e-12));
    for (int k = 0; k < ticks; ++k) {
      ASSERT_NEAR(tb[k].vhip_m.z, td[k].vhip_m.z, 1e-3 * kVoxel) << "floor " << z_new << ", tick " << k;
      ASSERT_NEAR(tb[k].force_n.z, td[k].force_n.z, kK * 1e-3 * kVoxel) << "floor " << z_new << ", tick " << k;
    }
    EXPECT_NEAR(norm(tb.back().force_n), kK * (z_new - 0.0145), kK * 1e-3 * kVoxel);
  }
}

// No version change: the trace is bit for bit the trace with the feature off, tick by tick,
// over approach, press, slide, a NaN HIP (fault), an absurd HIP (resync), lift-off and
// re-entry, for several parameter sets (period, recovery time, friction, force shading).
// The paper variant ignores versions: with edits its trace is also the feature-off one.
TEST(HriEdit, WithoutAnEditTheTraceIsTheOneWithoutTheFeature) {
  const Vec3 c{0.020, 0.020, 0.018};
  const SampleField s = ball(c, 0.010, 7), s2 = ball(c, 0.011, 8);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const HipAt hip = [&](int k) -> Vec3 {
    if (k == 350) return {nan, 0, 0};
    if (k == 500) return {5.0, 5.0, 5.0};
    const double a = 0.002 * k;
    const double r = 0.0115 - 0.003 * std::sin(0.01 * k) * std::sin(0.01 * k);
    return c + Vec3{r * std::sin(a) * 0.3, r * std::cos(a) * 0.2, r};
  };
  auto same = [](const HriTick& a, const HriTick& b) {
    return a.force_n.x == b.force_n.x && a.force_n.y == b.force_n.y && a.force_n.z == b.force_n.z &&
           a.vhip_m.x == b.vhip_m.x && a.vhip_m.y == b.vhip_m.y && a.vhip_m.z == b.vhip_m.z &&
           a.plane.valid == b.plane.valid && a.plane.p.x == b.plane.p.x && a.plane.p.z == b.plane.p.z &&
           a.plane.n.z == b.plane.n.z && a.contact == b.contact && a.plane_update == b.plane_update &&
           a.saturated == b.saturated && a.fault == b.fault && a.penetration_m == b.penetration_m;
  };
  for (int variant = 0; variant < 5; ++variant) {
    HriParams p = params(kPeriod, variant == 1 ? 1 : 5);
    if (variant == 2) p.recovery_time_s = 0.02;
    if (variant == 3) {
      p.friction.mu_s = 0.4;
      p.friction.mu_d = 0.3;
      p.force_shading = true;
    }
    if (variant == 4) p.variant = Variant::kPaper;
    HriParams p_off = p;
    p_off.edit_period_s = 0;
    const int ticks = 1500;
    HriRenderer on(p), off(p_off);
    // The paper variant sees an edit every 200 ticks; the robust one never.
    const FieldAt field = [&](int k) -> const SampleField& { return variant == 4 && (k / 200) % 2 ? s2 : s; };
    const auto t = drive(on, ticks, field, hip);
    const auto t0 = drive(off, ticks, field, hip);
    int contact = 0;
    for (int k = 0; k < ticks; ++k) {
      ASSERT_TRUE(same(t[k], t0[k])) << "parameter set " << variant << ", tick " << k;
      contact += t[k].contact;
    }
    EXPECT_GT(contact, 300) << "parameter set " << variant;  // the run does touch
  }
}

// An edit that tilts the surface 45 degrees under a HIP held 2 mm deep (review finding):
// the force turns from +z to the new normal (1, 0, 1)/sqrt 2. The force VECTOR eases over the
// edit period (1.17 N in 10 ticks, under 5 % of the limit per tick); without the ease it
// turned in one tick (|dF| = 1.17 N, about 7 times that). It still ends on the new plane's
// force (analytic: K times the HIP's depth below the tilted plane, along its normal).
TEST(HriEdit, AnEditThatTiltsTheSurfaceTurnsTheForceGradually) {
  const SampleField a = floor_at(0.010, 1);
  const double s = std::sqrt(0.5);
  SampleField b = plane_field({s, 0, s}, {kX, kY, 0.010});
  b.version = 2;
  const int edit = 300, ticks = 400;
  HriRenderer on(params());
  const auto t = drive(on, ticks, switch_at(a, b, edit), press_to(0.008));
  EXPECT_GT(norm(t[edit - 1].force_n), 1.0);  // pressed before the edit
  EXPECT_LE(max_vector_step(t, edit - 1, ticks), kStep * (1 + 1e-12));
  EXPECT_LE(max_step(t), kStep * (1 + 1e-12));
  const Vec3 n{s, 0, s};
  const double depth = dot(n, Vec3{kX, kY, 0.010} - Vec3{kX, kY, 0.008});  // 2 mm * cos 45
  const Vec3 want = n * (kK * depth);
  EXPECT_LT(norm(t[ticks - 1].force_n - want), 1e-3) << "settled force on the tilted plane";
}

// A small force turns far: held 0.3 mm deep, an edit tilts the surface 60 degrees. No
// degrees-per-tick cap exists: the turn follows the eased force vector, spread over the edit
// period (the largest turn of one tick is under half the whole turn), and ends along the new
// normal; with the ease off (period 0) the whole turn comes in one tick. Truth: the analytic
// normals of the two planes.
TEST(HriEdit, AnEditTurnsASmallForceOverTheEditPeriod) {
  const SampleField a = floor_at(0.010, 1);
  const Vec3 n{std::sin(M_PI / 3), 0, std::cos(M_PI / 3)};
  SampleField b = plane_field(n, {kX, kY, 0.010});
  b.version = 2;
  const int edit = 300, ticks = 400;
  auto worst_turn = [&](double period_s, Vec3* last) {
    HriRenderer r(params(period_s));
    const auto t = drive(r, ticks, switch_at(a, b, edit), press_to(0.0097));
    double worst = 0;
    for (int k = edit; k < ticks; ++k) {
      const double m0 = norm(t[k - 1].force_n), m1 = norm(t[k].force_n);
      if (!(m0 > 0 && m1 > 0)) continue;
      worst = std::max(worst, std::acos(std::clamp(dot(t[k].force_n, t[k - 1].force_n) / (m0 * m1), -1.0, 1.0)));
    }
    *last = t[ticks - 1].force_n;
    return worst * 180.0 / M_PI;
  };
  Vec3 last_on, last_off;
  const double on = worst_turn(kPeriod, &last_on), off = worst_turn(0.0, &last_off);
  std::printf("edit tilting the surface 60 deg under 0.24 N: largest turn per tick %.2f deg eased, %.2f deg without\n",
              on, off);
  EXPECT_LT(on, 30.0);
  EXPECT_GT(off, 59.0);
  EXPECT_GT(dot(last_on / norm(last_on), n), 0.9999);  // it still ends along the new normal
}

// Steady drilling: the floor recedes 0.3 mm every 10 ticks (one edit per edit period) under
// a HIP that follows at the same mean speed (30 mm/s). Each edit stands for 10 ms of cutting:
// eased over them, |F| stays level (within a tenth of K * 0.3 mm = 0.24 N, the one tick of the
// user's own motion in the step); published as steps with no ease (a 1 ms period), |F| dips
// by most of 0.24 N at every edit and recovers (the buzz at the edit rate).
TEST(HriEdit, SteadyDrillingFeelsNoDipAtTheEditRate) {
  constexpr double kDelta = 3e-4;  // floor receded per edit [m]
  constexpr int kEdits = 30, e0 = 200, ticks = e0 + kEase * kEdits;
  std::vector<SampleField> floors;
  for (int i = 0; i <= kEdits; ++i) floors.push_back(floor_at(0.016 - kDelta * i, std::uint64_t(i + 1)));
  const FieldAt field = [&](int k) -> const SampleField& {
    return floors[std::size_t(k < e0 ? 0 : 1 + (k - e0) / kEase)];
  };
  const HipAt hip = [](int k) {  // 1.5 mm deep, then down at kDelta per edit period
    return Vec3{kX, kY, std::max(0.0145, 0.018 - 5e-5 * k) - (k < e0 ? 0.0 : kDelta * (k - e0) / kEase)};
  };
  auto spread = [&](double period_s) {
    HriRenderer r(params(period_s));
    const auto t = drive(r, ticks, field, hip);
    double lo = 1e9, hi = -1e9;
    for (int k = e0 + 5 * kEase; k < ticks; ++k) {  // the steady part
      EXPECT_TRUE(t[k].contact) << k;
      lo = std::min(lo, norm(t[k].force_n));
      hi = std::max(hi, norm(t[k].force_n));
    }
    return hi - lo;
  };
  const double eased = spread(kPeriod), stepped = spread(0.001);
  std::printf("steady drill, 0.3 mm per 10 ms edit: |F| max - min %.4f N eased, %.4f N stepped\n", eased, stepped);
  EXPECT_LT(eased, 0.1 * kK * kDelta);
  EXPECT_GT(stepped, 0.7 * kK * kDelta);
}

// An edit far from the probe (its snapshot's changed box more than the reach away) is not
// an edit for the servo: no plane re-evaluation, no ease; the trace is bit for bit the one
// without the new snapshot. The same snapshot with its box over the probe, or with no box
// (unknown), is an edit (the plane is re-evaluated on that tick).
TEST(HriEdit, AnEditFarFromTheProbeLeavesTheTraceAlone) {
  const SampleField a = floor_at(0.010, 3);
  ASSERT_GE(a.grid.dims[0], 24);
  SampleField far = a;
  far.version = 4;
  // Material added in the corner brick, 8 voxels, far from the probe at (16, 16, ~8) voxels.
  for (int z = 0; z < 4; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) far.samples[a.grid.index(x, y, z + 20)].value = 1000.f;
  far.changed = {{0, 0, 20}, {4, 4, 24}, true};
  SampleField near = far, unknown = far;
  near.changed = {{12, 12, 4}, {20, 20, 12}, true};
  unknown.changed = {};
  const auto same = [](const HriTick& x, const HriTick& y) {
    return x.force_n.x == y.force_n.x && x.force_n.y == y.force_n.y && x.force_n.z == y.force_n.z &&
           x.vhip_m.x == y.vhip_m.x && x.vhip_m.y == y.vhip_m.y && x.vhip_m.z == y.vhip_m.z &&
           x.plane_update == y.plane_update && x.contact == y.contact;
  };
  const HipAt hip = press_to(0.0075);  // 2.5 mm into the floor, held
  const int ticks = 400, edit = 203;   // not a plane-update tick of its own (n = 5)
  HriRenderer r0(params()), r_far(params()), r_near(params()), r_unknown(params());
  const auto t0 = drive(r0, ticks, [&](int) -> const SampleField& { return a; }, hip);
  const auto t_far = drive(r_far, ticks, switch_at(a, far, edit), hip);
  const auto t_near = drive(r_near, ticks, switch_at(a, near, edit), hip);
  const auto t_unknown = drive(r_unknown, ticks, switch_at(a, unknown, edit), hip);
  ASSERT_TRUE(t0[edit].contact) << "the probe must press on the floor when the edit comes";
  for (int k = 0; k < ticks; ++k) ASSERT_TRUE(same(t0[k], t_far[k])) << "far edit, tick " << k;
  EXPECT_FALSE(t0[edit].plane_update);
  EXPECT_TRUE(t_near[edit].plane_update) << "an edit over the probe was not seen";
  EXPECT_TRUE(t_unknown[edit].plane_update) << "a snapshot without a changed box was not an edit";
}

// A snapshot's changed box covers the step from the version just before it only. When two
// publications land between two ticks, the renderer never reads the first: the floor raised
// 1.5 mm under the held probe (v4, box over the probe) followed by a version that changed
// nothing near it (v5, box in a far corner). Read as v3 -> v5, that is still the raise under
// the probe: an edit, |F| eased as when every version is read.
TEST(HriEdit, ASkippedVersionIsAnEditWhateverTheNewestBox) {
  const SampleField a = floor_at(0.010, 3);
  SampleField raised = floor_at(0.0115, 4);
  raised.changed = {{12, 12, 4}, {20, 20, 16}, true};
  SampleField after = raised;
  after.version = 5;
  after.changed = {{0, 0, 28}, {4, 4, 32}, true};
  const HipAt hip = press_to(0.0075);
  const int ticks = 400, edit = 203;
  const FieldAt each = [&](int k) -> const SampleField& { return k < edit ? a : k == edit ? raised : after; };
  const FieldAt skipped = switch_at(a, after, edit);
  HriRenderer r_each(params()), r_skip(params());
  const auto t_each = drive(r_each, ticks, each, hip);
  const auto t_skip = drive(r_skip, ticks, skipped, hip);
  ASSERT_TRUE(t_each[edit].contact) << "the probe must press on the floor when the edit comes";
  const double step_each = max_step(t_each), step_skip = max_step(t_skip);
  std::printf("floor raised 1.5 mm under the probe: largest |F| step %.3f N reading every version, %.3f N "
              "with the raise's version skipped (bound %.3f N)\n", step_each, step_skip, kStep);
  EXPECT_LE(step_each, kStep + 1e-9);
  EXPECT_LE(step_skip, kStep + 1e-9);
  EXPECT_TRUE(t_skip[edit].plane_update) << "the skipped raise was not seen as an edit";
}

// A recovery ramp that starts during an edit ease (a plane update 3 ticks after the carve
// finds the floor another 0.5 mm lower: the same snapshot version, so not an edit) starts
// from the force sent, the ease's offset included: it takes the ease over. Every change here
// is downward, so |F| never rises (the ease's offset added on top of the ramp rose by 0.2 N).
TEST(HriEdit, ARampStartedDuringTheEaseTakesItOver) {
  const SampleField before = floor_at(0.016, 1), after = floor_at(0.015, 2);
  SampleField lower = floor_at(0.0145, 2);
  const int edit = 151, ticks = 260;  // the n-tick update (n = 5) comes at 155, mid-ease
  HriParams p = params();
  p.recovery_time_s = 0.02;
  HriRenderer r(p);
  const FieldAt field = [&](int k) -> const SampleField& { return k < edit ? before : (k < edit + 3 ? after : lower); };
  const auto t = drive(r, ticks, field, press_to(0.0135));
  EXPECT_NEAR(norm(t[edit - 1].force_n), kK * 0.0025, 1e-5);
  bool updated = false;
  for (int k = edit; k < ticks; ++k) {
    EXPECT_LE(norm(t[k].force_n), norm(t[k - 1].force_n) + 1e-9) << k;
    updated = updated || (k > edit && k < edit + kEase && t[k].plane_update);
  }
  EXPECT_TRUE(updated) << "no plane update during the ease: the case is not tested";
  EXPECT_NEAR(norm(t.back().force_n), kK * 0.001, 1e-5);
}
