// test_hri_sharp_edge.cpp - the point probe pressed into the 255 plateau of a box with 90-deg
// edges (a CT of metal: voxels 255 inside, 0 outside, isovalue 108.57 as the shipped engine
// block's) and stroked over an edge: the proxy (VHIP) stays on the trilinear isosurface. On
// the engine block (plan "ray") the embedded search found a surface point p 3.5 mm away on
// another face and the proxy, the HIP projected on that plane, landed 2.3 mm from p, in air.
// The truth: the trilinear field of a box of voxels is the product of three 1D hat ramps
// (analytic, not the renderer's sampling), and the VHIP's distance to its isosurface is
// found by a dense search of that product around the VHIP.
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

constexpr double kVox = 1e-3;                 // [m]
constexpr double kTau = 108.57421875;         // the engine block's isovalue
constexpr int kLo[3] = {8, 8, 0}, kHi[3] = {24, 32, 20};  // the box's voxels (inclusive)

// 1D linear interpolation of the box's indicator at x [voxels].
double ramp(double x, int lo, int hi) { return std::clamp(std::min(x - (lo - 1), (hi + 1) - x), 0.0, 1.0); }
// The trilinear field of the box minus the isovalue at x [m] (positive inside).
double truth(const Vec3& x) {
  return 255.0 * ramp(x.x / kVox, kLo[0], kHi[0]) * ramp(x.y / kVox, kLo[1], kHi[1]) * ramp(x.z / kVox, kLo[2], kHi[2]) -
         kTau;
}
// The distance [m] from x to the isosurface truth = 0: the first sphere round x (radii a
// fiftieth of a voxel apart, 2000 directions on a Fibonacci lattice: 0.08 rad apart) that
// holds a point of the other sign (returns reach when none within it).
double to_surface(const Vec3& x, double reach) {
  const bool in = truth(x) > 0.0;
  const int kDirs = 2000;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (double r = 0.02 * kVox; r < reach; r += 0.02 * kVox)
    for (int i = 0; i < kDirs; ++i) {
      const double z = 1.0 - 2.0 * (i + 0.5) / kDirs, s = std::sqrt(1.0 - z * z);
      const Vec3 d{s * std::cos(golden * i), s * std::sin(golden * i), z};
      if ((truth(x + d * r) > 0.0) != in) return r;
    }
  return reach;
}

}  // namespace

// DISABLED (issue 64 is open): fails on main, the proxy 0.86 mm off the isosurface on a plane
// update and 1.14 mm on a slide (n = 10, 3 mm deep; n = 1: 0.70 mm). Run it with
// --gtest_also_run_disabled_tests. Fixes tried in the plane update (tick_general's set_plane),
// each passing this test, each breaking something else: pinning N from the HIP to p where the
// proxy lies over half a voxel from p (engine plan "ray": saturated ticks 326 -> 1530; head CT
// plan "surface" 0 -> 418; HriRidges seed 4's 4-voxel ridge wraps at 0.8 at n = 10); the same
// only where the proxy lies in air (ray: 326 -> 593, HriRidges seed 4 again); the surface under
// the proxy, else pinned (ray: 1001 lift ticks pull inward, 0.94 N, cli_run_engine_lift fails);
// the surface under the proxy alone (this test still fails, 55-deg direction step on ray).
TEST(HriSharpEdge, DISABLED_TheProxyStaysOnTheIsosurfaceOverAMetalEdge) {
  const SampleField f = isotouch::test::scan_like_field(
      {40, 40, 32}, {kVox, kVox, kVox}, [](const Vec3& x) { return truth(x); }, 0.0, 1u);
  const HriParams p = isotouch::test::scene_servo();
  const double top = (kHi[2] + 1 - kTau / 255.0) * kVox;   // the flat top face, z [m]
  const double side = (kHi[0] + 1 - kTau / 255.0) * kVox;  // the +x side face, x [m]
  // On a plane update the proxy is at most half a voxel from the plane's point p, on the
  // surface (or on the material's side of it); between updates it slides at most half a voxel
  // from where the update put it (slid_far): half a voxel on update ticks, a voxel on all.
  const double bound_update = 0.5 * kVox, bound = 1.0 * kVox;
  for (const int n : {1, 10}) {
    for (const double depth : {0.0015, 0.0030}) {  // into the plateau (one voxel from the face)
      HriParams pn = p;
      pn.plane_update_period = n;
      HriRenderer r(pn);
      double sum_d2 = 0, max_d = 0, max_du = 0;
      Vec3 worst{};
      long contact = 0;
      for (int k = 0; k < 1600; ++k) {
        const double t = k * 1e-3;
        const double down = std::min(0.02 * t, 0.002 + depth);                // 20 mm/s in
        const double along = std::clamp(0.04 * (t - 0.3), 0.0, 0.014);        // 40 mm/s over the edge
        const double up = std::max(0.0, 0.02 * (t - 0.75));                   // then lifted
        const Vec3 hip{side - 0.008 + along, 0.020, top + 0.002 - down + up};
        const HriTick out = r.tick(f, hip);
        if (!out.contact) continue;
        const double d = to_surface(out.vhip_m, 4.0 * kVox);
        sum_d2 += d * d;
        if (out.plane_update) max_du = std::max(max_du, d);
        if (d > max_d) {
          max_d = d;
          worst = out.vhip_m;
        }
        ++contact;
      }
      const double rms = contact ? std::sqrt(sum_d2 / double(contact)) : 0.0;
      std::printf("n = %d, depth %.1f mm: %ld contact ticks, VHIP to isosurface RMS %.3f mm, max %.3f mm at (%.2f, %.2f, %.2f) mm; on plane updates max %.3f mm\n",
                  n, depth * 1e3, contact, rms * 1e3, max_d * 1e3, worst.x * 1e3, worst.y * 1e3, worst.z * 1e3, max_du * 1e3);
      EXPECT_GT(contact, 300);
      EXPECT_LE(max_du, bound_update) << "n = " << n << ", depth " << depth;
      EXPECT_LE(max_d, bound) << "n = " << n << ", depth " << depth;
    }
  }
}
