// eval::measure_channel and eval::find_breakthrough against shapes and traces made by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "isotouch/eval/drill_channel.h"
#include "isotouch/tests/drilled_slab.h"

using isotouch::core::Isosurface;
using isotouch::core::Vec3;
using isotouch::engine::Volume;
using namespace isotouch::eval;

namespace {

// The slab and its hole (tests/drilled_slab.h).
Volume slab(double (*radius)(double), bool hole) { return isotouch::test::drilled_slab(radius, hole); }

std::vector<Vec3> axis_path() {
  std::vector<Vec3> c;
  for (int k = 0; k <= 60; ++k) c.push_back({0.010, 0.010, 0.005 + k * 0.25e-3});
  return c;
}

}  // namespace

TEST(DrillChannel, OpenRadiusOfAStraightHole) {
  const Volume before = slab(+[](double) { return 0.0; }, false);
  const Volume after = slab(+[](double) { return 4.0; }, true);
  const ChannelFigures f = measure_channel(before, after, Isosurface{500, isotouch::core::InsideIs::kAbove}, axis_path(),
                                           {0, 0, 1}, 4e-3);
  ASSERT_TRUE(f.measured);
  EXPECT_GT(f.slices, 30);
  // The trilinear surface of a voxelised 4 mm hole lies within a voxel of 4 mm.
  EXPECT_NEAR(f.min_open_radius_m, 4e-3, 0.5e-3);
  EXPECT_NEAR(f.min_fraction, 1.0, 0.13);
}

TEST(DrillChannel, AWaistIsTheNarrowestSlice) {
  const Volume before = slab(+[](double) { return 0.0; }, false);
  const Volume after = slab(+[](double z) { return std::abs(z - 15) < 1.0 ? 1.0 : 4.0; }, true);
  const ChannelFigures f = measure_channel(before, after, Isosurface{500, isotouch::core::InsideIs::kAbove}, axis_path(),
                                           {0, 0, 1}, 4e-3);
  ASSERT_TRUE(f.measured);
  EXPECT_NEAR(f.min_open_radius_m, 1e-3, 0.5e-3);
  EXPECT_LT(f.min_fraction, 0.4);
  EXPECT_NEAR(f.min_at_depth_m, 0.005, 1.5e-3);  // the waist at z = 15 mm, the slab from z = 10 mm
}

TEST(DrillChannel, BreakthroughIsTheDropThatStays) {
  std::vector<double> t, f;
  std::vector<char> down;
  for (int k = 0; k < 2000; ++k) {
    t.push_back(k * 1e-3);
    double v = 0.6;
    if (k >= 800 && k < 810) v = 0.0;  // a 10 ms dip: not a breakthrough
    if (k >= 1500) v = std::max(0.0, 0.6 - 0.03 * (k - 1500));  // falls over 20 ms and stays
    f.push_back(v);
    down.push_back(k >= 100);
  }
  const Breakthrough b = find_breakthrough(t, f, down, 0.2);
  ASSERT_TRUE(b.found);
  EXPECT_NEAR(b.t_s, 1.519, 1.5e-3);  // the first tick at or below 0.02 N
  EXPECT_NEAR(b.from_n, 0.6, 1e-9);
  EXPECT_NEAR(b.fall_s, 0.018, 2.5e-3);
  // The button up before the fall: no breakthrough.
  std::vector<char> up = down;
  for (int k = 1400; k < 2000; ++k) up[std::size_t(k)] = 0;
  EXPECT_FALSE(find_breakthrough(t, f, up, 0.2).found);
}
