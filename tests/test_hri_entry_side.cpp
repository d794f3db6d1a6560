// test_hri_entry_side.cpp - the thin-feature hold (HriRenderer::hold_entry_side) on a state
// set by hand: the cases a tick sequence reaches only rarely (a held plane whose normal
// differs from the entry normal the hold turns it back to). Truth from the analytic slab.
#include <gtest/gtest.h>

#include <cmath>

#include "isotouch/servo/hri.h"
#include "field_builders.h"
#include "isotouch/tests/scene_servo.h"

using namespace isotouch::core;
using namespace isotouch::servo;

namespace isotouch::servo {
// One hold_entry_side on a renderer whose contact state the test sets.
struct HriRendererTest {
  static VirtualPlane hold(HriRenderer& r, const FieldView& field, const Vec3& hip, const VirtualPlane& held,
                           const VirtualPlane& turned, const Vec3& entry_n, const Vec3& vhip, double voxel) {
    r.plane_ = turned;  // the plane this update found (turned beyond the entry cone)
    r.entry_n_ = entry_n;
    r.entry_hip_ = hip;
    r.entry_vhip_ = vhip;
    r.entry_held_ = false;
    r.vhip_ = vhip;
    HriRenderer::TickOut out;
    r.hold_entry_side(field, hip, true, held, 1000.0, voxel, out);
    return r.plane_;
  }
};
}  // namespace isotouch::servo

// The held plane's point moves up to the face found from the HIP along the normal kept, at
// most the HIP's depth along that normal plus a voxel in one update (the face search's
// reach). Where the kept normal is the entry normal and the held plane's normal is turned
// 20-45 deg from it, the depth that bounds the search is the one along the entry normal:
// measured along the held normal (larger here, the held point lying off to the side) the
// search found a face farther than that and the proxy went up past the bound in one tick.
// A slab 2 mm thick (1 mm voxels, top face z = 21 mm), the HIP 1.4 mm below its top face
// (past its middle: the hold acts), the held plane's point 0.2 mm above the HIP along the
// entry normal and 4 mm to the side: the face lies 1.4 mm above the HIP, beyond the reach
// 0.2 + 1 mm, so the kept plane stays 0.2 mm above the HIP and the force is K * 0.2 mm.
TEST(HriEntrySide, TheHeldPointMovesAtMostTheDepthAlongTheKeptNormalPlusAVoxel) {
  const double voxel = 1e-3, top = 0.021, w = 0.002;
  const SampleField f = isotouch::test::sample_analytic(
      {40, 40, 40}, {voxel, voxel, voxel}, {0, 0, 0},
      [=](const Vec3& x) { return 1000.0 * (0.5 * w - std::abs(x.z - (top - 0.5 * w))); },
      [=](const Vec3& x) { return Vec3{0, 0, x.z >= top - 0.5 * w ? -1000.0 : 1000.0}; });
  const Vec3 z{0, 0, 1};
  const Vec3 hip{0.020, 0.020, top - 0.0014};
  const double b = 0.0002, a = 0.004;  // the held point: b above the HIP along z, a to the side
  for (const double deg : {20.0, 30.0, 45.0}) {
    const double t = deg * M_PI / 180.0;
    VirtualPlane held;
    held.n = Vec3{std::sin(t), 0, std::cos(t)};
    held.p = hip + Vec3{a, 0, b};
    held.valid = true;
    VirtualPlane turned;  // 60 deg from the entry normal: beyond the cone
    turned.n = Vec3{-std::sin(M_PI / 3), 0, std::cos(M_PI / 3)};
    turned.p = hip + turned.n * 0.0005;
    turned.valid = true;
    const HriParams p = isotouch::test::scene_servo();
    HriRenderer r(p);
    const VirtualPlane kept = HriRendererTest::hold(r, f, hip, held, turned, z, hip + z * 0.0014, voxel);
    ASSERT_TRUE(kept.valid);
    EXPECT_NEAR(dot(kept.n, z), 1.0, 1e-12) << deg << " deg";  // turned back to the entry normal
    // The face (1.4 mm above the HIP) lies beyond the reach along z (b + voxel = 1.2 mm):
    // the plane stays at the held point's height, b above the HIP.
    const double depth = dot(kept.n, kept.p - hip);
    EXPECT_NEAR(depth, b, 1e-9) << deg << " deg: the plane " << depth * 1e3 << " mm above the HIP";
    EXPECT_LE(depth, b + voxel) << deg << " deg";
  }
}
