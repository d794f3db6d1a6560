// test_hri_falling_plate.cpp - the point probe pressed past the middle of a plate 4 voxels
// thick (a skull-like bone wall) and stroked where the plate's surface falls away under the
// stroke, then lifted: the proxy follows the surface down (the VHIP stays on it) and no
// release lets go of more than 5 % of the force limit in one tick (the head CT's stroke,
// scenes/head.json, released 2.4 N in one tick when a held plane stayed above such a surface).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "isotouch/servo/hri.h"
#include "isotouch/tests/scene_servo.h"
#include "isotouch/tests/thin_ridges.h"

using namespace isotouch::core;
using namespace isotouch::servo;

namespace {

// The plate's top surface height [m] at y [m]: flat to y = 20 mm, then falling 0.4 mm per mm.
double top_z(double y) { return 0.020 - 0.4 * std::max(0.0, y - 0.020); }

}  // namespace

// K = 800 N/m, limit 3.3 N, bar 0.165 N and 0.5 mm. Main's renderer before the thin-feature
// hold released 0.615 N at n = 1 (HIP 0.07 mm deep, the plane 0.7 mm above the fallen
// surface); the hold rules without lowering the held point 2.41 N at n = 10 (the head CT's
// failure). With the held point lowered where the wall under the new face is as thick as at
// entry: n = 1 0.10 N, RMS 0.07 mm; n = 10 0 N, RMS 0.40 mm.
TEST(HriFallingPlate, TheProxyFollowsASurfaceFallingAwayAndLetsGoWithoutAStep) {
  const double thick = 0.004, sigma = 0.0004;  // 4 voxels of 1 mm, partial-volume edges
  const SampleField f = isotouch::test::scan_like_field(
      {48, 48, 32}, {1e-3, 1e-3, 1e-3},
      [=](const Vec3& x) {
        const double h = top_z(x.y);
        return 1000.0 * (isotouch::test::phi((h - x.z) / sigma) - isotouch::test::phi((h - thick - x.z) / sigma) - 0.5);
      },
      1e-6, 1u);
  const HriParams p = isotouch::test::scene_servo();
  for (const int n : {1, 10}) {
    HriParams pn = p;
    pn.plane_update_period = n;
    HriRenderer r(pn);
    const double press = 0.9 * p.force_limit_n / p.stiffness_n_per_m;  // past the plate's middle
    double prev_f = 0, max_release = 0, release_t = 0, sum_d2 = 0, max_d = 0;
    long contact = 0;
    for (int k = 0; k < 3000; ++k) {
      const double t = k * 1e-3;
      const double down = std::min(0.02 * t, 0.003 + press);                // 20 mm/s in
      const double along = std::clamp(0.04 * (t - 0.5), 0.0, 0.016);        // 40 mm/s stroke
      const double up = std::max(0.0, 0.02 * (t - 1.0));                    // then lifted
      const Vec3 hip{0.024, 0.012 + along, top_z(0.012) + 0.003 - down + up};
      const HriTick out = r.tick(f, hip);
      const double fm = norm(out.force_n);
      if (!out.contact && prev_f > max_release) {
        max_release = prev_f;
        release_t = t;
      }
      prev_f = out.contact ? fm : 0.0;
      if (!out.contact) continue;
      // The VHIP's distance to the top surface, across the local slope [m].
      const double d = std::abs(out.vhip_m.z - top_z(out.vhip_m.y)) / std::sqrt(1.0 + (out.vhip_m.y > 0.020 ? 0.16 : 0.0));
      sum_d2 += d * d;
      max_d = std::max(max_d, d);
      ++contact;
    }
    const double rms = contact ? std::sqrt(sum_d2 / double(contact)) : 0.0;
    std::printf("n = %d: %ld contact ticks, largest release %.3f N (t = %.3f s, HIP %.2f mm below the top), VHIP to surface RMS %.3f mm, max %.3f mm\n", n,
                contact, max_release, release_t, 1e3 * (top_z(0.012 + std::clamp(0.04 * (release_t - 0.5), 0.0, 0.016)) - (top_z(0.012) + 0.003 - std::min(0.02 * release_t, 0.003 + press) + std::max(0.0, 0.02 * (release_t - 1.0)))), rms * 1e3, max_d * 1e3);
    EXPECT_GT(contact, 500);
    EXPECT_LE(max_release, 0.05 * p.force_limit_n) << "n = " << n;
    EXPECT_LT(rms, 0.5e-3) << "n = " << n;
  }
}
