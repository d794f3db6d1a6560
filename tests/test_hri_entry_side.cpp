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
    r.entry_proxy_ = vhip;
    r.entry_held_ = false;
    r.vhip_ = vhip;
    HriRenderer::TickOut out;
    r.hold_entry_side(field, hip, true, held, 1000.0, voxel, out);
    return r.plane_;
  }
  // The same after a contact that entered at entry_hip (the proxy at entry_vhip, entry
  // normal entry_n) and went deepest along it at deep_hip (deep_depth behind the plane held
  // then), the proxy now at vhip.
  static VirtualPlane hold_after(HriRenderer& r, const FieldView& field, const Vec3& hip, const VirtualPlane& held,
                                 const VirtualPlane& turned, const Vec3& entry_n, const Vec3& entry_hip,
                                 const Vec3& entry_vhip, const Vec3& deep_hip, double deep_depth, const Vec3& vhip,
                                 double voxel) {
    r.plane_ = turned;
    r.entry_n_ = entry_n;
    r.entry_hip_ = entry_hip;
    r.entry_vhip_ = entry_vhip;
    r.entry_proxy_ = entry_vhip;
    r.entry_deep_hip_ = deep_hip;
    r.entry_deep_depth_ = deep_depth;
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

namespace {
// A long cylinder of radius 1.5 mm along y (1 mm voxels, axis at x = z = 20 mm): 3 voxels
// thick, as the scan-like cylinders of tests/thin_ridges.h. Its crest faces +z.
const double kR = 0.0015;
const Vec3 kAxis{0.020, 0.020, 0.020};
SampleField cylinder_y() {
  return isotouch::test::sample_analytic(
      {40, 40, 40}, {1e-3, 1e-3, 1e-3}, {0, 0, 0},
      [](const Vec3& x) { return 1000.0 * (kR - std::hypot(x.x - kAxis.x, x.z - kAxis.z)); },
      [](const Vec3& x) {
        const double dx = x.x - kAxis.x, dz = x.z - kAxis.z, r = std::hypot(dx, dz);
        return r > 0 ? Vec3{-1000.0 * dx / r, 0, -1000.0 * dz / r} : Vec3{};
      });
}
// The unit normal of the cylinder's surface `deg` degrees round from its crest toward +x,
// and the plane tangent there.
Vec3 round_from_crest(double deg) { return Vec3{std::sin(deg * M_PI / 180.0), 0, std::cos(deg * M_PI / 180.0)}; }
VirtualPlane tangent(double deg) {
  VirtualPlane pl;
  pl.n = round_from_crest(deg);
  pl.p = kAxis + pl.n * kR;
  pl.valid = true;
  return pl;
}
// Where the plane puts the proxy for this HIP (eq. 2): the HIP projected onto it.
Vec3 proxy_on(const VirtualPlane& pl, const Vec3& hip) { return hip + pl.n * dot(pl.n, pl.p - hip); }
}  // namespace

// The HIP pressed along the entry normal past the cylinder's axis, the HIP still: the plane
// iteration carried the proxy 15 deg round the crest (0.39 mm across the entry normal, the
// HIP none) and this update's plane is 18 deg round, inside the 20-deg entry cone. That turn
// is the iteration's, not the hand's: the side is held (the plane faces the entry normal
// again) at once, not only once a plane leaves the cone. Before, the cone alone let it go on:
// on a 2-voxel cylinder on 1 x 1 x 3 mm voxels whose contact normal came 25 deg off the
// crest's, it went 42 deg round and the stroke slid the proxy past the axis (HriRidges seed 13).
TEST(HriEntrySide, APlaneTheIterationTurnedInsideTheEntryConeIsTurnedBack) {
  const SampleField f = cylinder_y();
  const Vec3 e = round_from_crest(0.0);  // the entry normal: the crest's
  const Vec3 entry_hip = kAxis + e * (kR - 0.0002), hip = kAxis - e * 0.0002;  // pressed 1.5 mm along -e
  const VirtualPlane held = tangent(15.0), turned = tangent(18.0);
  HriRenderer r(isotouch::test::scene_servo());
  const VirtualPlane kept = HriRendererTest::hold_after(r, f, hip, held, turned, e, entry_hip, kAxis + e * kR,
                                                        entry_hip, 0.0002, proxy_on(held, hip), 1e-3);
  ASSERT_TRUE(kept.valid);
  EXPECT_NEAR(dot(kept.n, e), 1.0, 1e-12) << "the plane kept is " << std::acos(std::min(1.0, dot(kept.n, e))) * 180 / M_PI
                                          << " deg round the crest";
  EXPECT_LT(dot(kept.n, hip - kept.p), 0.0);  // the HIP behind it: a force toward the entry side
}

// The HIP pressed straight down past the axis (0.25 mm below it) along the crest's normal,
// then stroked 1.35 mm across toward +x; the entry normal the contact took is 25 deg off the
// crest's, toward the stroke (a scan's blocky crest). Along that normal the stroked HIP is
// short of the middle again (0.35 mm from the near face, 1.04 from the far one), as it is
// along this update's plane, 80 deg round the crest: neither test holds, and that plane puts
// the proxy 0.21 mm below the axis, on the far side. The HIP was past the middle at its
// deepest, so the side is held: the proxy stays above the axis.
TEST(HriEntrySide, AHipThatWentPastTheMiddleHoldsTheSideAfterAStrokeAcross) {
  const SampleField f = cylinder_y();
  const Vec3 z{0, 0, 1}, x{1, 0, 0};
  const Vec3 e = round_from_crest(25.0);  // the entry normal the contact took
  const Vec3 entry_hip = kAxis + z * 0.0010, deep = kAxis - z * 0.00025, hip = deep + x * 0.00135;
  const VirtualPlane held = tangent(40.0), turned = tangent(80.0);
  ASSERT_LT(dot(proxy_on(turned, hip) - kAxis, z), -0.1e-3);  // this update's plane: past the axis
  HriRenderer r(isotouch::test::scene_servo());
  const double deep_depth = 0.00172;  // deep's depth along e under the surface there
  const VirtualPlane kept = HriRendererTest::hold_after(r, f, hip, held, turned, e, entry_hip, kAxis + e * kR, deep,
                                                        deep_depth, proxy_on(held, hip), 1e-3);
  ASSERT_TRUE(kept.valid);
  const Vec3 proxy = proxy_on(kept, hip);
  EXPECT_GT(dot(proxy - kAxis, z), 0.0) << "the proxy " << dot(proxy - kAxis, z) * 1e3 << " mm above the axis";
  EXPECT_LT(dot(kept.n, hip - kept.p), 0.0);  // the HIP behind the plane kept
  EXPECT_GT(dot(kept.n, z), 0.0);             // its force toward the entry side
}
