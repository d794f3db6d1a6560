// The default touch scene made for a volume (run/volume_scene): where the probe comes from on
// shapes whose answer is known, and the scene it writes.
#include <gtest/gtest.h>

#include <cmath>

#include "isotouch/engine/synthetic.h"
#include "isotouch/run/volume_scene.h"

namespace isotouch::run {
namespace {

/// A three-level volume (0 air, 1000 soft, 2000 hard: the thresholds fall between them)
/// of 40^3 voxels of 1 mm: air everywhere, then what `fill` sets.
template <class F>
engine::Volume three_levels(F fill) {
  engine::Volume v;
  v.grid.dims = {40, 40, 40};
  v.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  v.voxels.assign(40 * 40 * 40, 0.0f);
  for (int z = 0; z < 40; ++z)
    for (int y = 0; y < 40; ++y)
      for (int x = 0; x < 40; ++x) v.voxels[v.grid.index(x, y, z)] = fill(x, y, z);
  v.update_stats();
  return v;
}

TEST(VolumeScene, ApproachesTheSurfaceNearestItsFace) {
  // A hard block spanning x 12..27, y 8..31, z 5..34: from the low z face 5 voxels of air,
  // the nearest face; the others have 8 (y) and 12 (x).
  const engine::Volume v = three_levels([](int x, int y, int z) {
    return x >= 12 && x <= 27 && y >= 8 && y <= 31 && z >= 5 && z <= 34 ? 2000.0f : 0.0f;
  });
  const Approach a = choose_approach(v, core::Isosurface{1500, core::InsideIs::kAbove});
  ASSERT_TRUE(a.found);
  EXPECT_EQ(a.axis, 2);
  EXPECT_EQ(a.sign, +1);  // from the low face toward higher indices
  EXPECT_NEAR(a.air_m, 5e-3, 1e-12);
}

TEST(VolumeScene, SkipsAFaceWhereTheScanWasCroppedThroughTissue) {
  // As a head cut at its top: soft tissue (below the isovalue) fills the low z face's centre
  // and reaches a hard floor 3 voxels in; from the sides 10 voxels of air come first (12 from
  // the high z face). The
  // cropped face is nearer but is not taken: the probe would start inside the tissue.
  const engine::Volume v = three_levels([](int x, int y, int z) {
    const bool hard = x >= 10 && x <= 29 && y >= 10 && y <= 29 && z >= 3 && z <= 27;
    const bool soft = x >= 12 && x <= 27 && y >= 12 && y <= 27 && z <= 2;
    return soft ? 1000.0f : hard ? 2000.0f : 0.0f;
  });
  const Approach a = choose_approach(v, core::Isosurface{1500, core::InsideIs::kAbove});
  ASSERT_TRUE(a.found);
  EXPECT_NE(a.axis, 2) << describe_approach(v, a);
  EXPECT_NEAR(a.air_m, 10e-3, 1e-12);
}

TEST(VolumeScene, SphereSceneTouchesFromOutside) {
  // A signed-distance sphere (positive inside: inside "above" 0). No face is in its lowest
  // Otsu class (the corners are farther out than the faces' centres), so any face with room
  // counts; every face has the same air and the first in order (low x face) is taken.
  const engine::Volume v = engine::make_sphere({48, 48, 48}, 1e-3, 15);
  const Approach a = choose_approach(v, core::Isosurface{0, core::InsideIs::kAbove});
  ASSERT_TRUE(a.found);
  EXPECT_EQ(a.axis, 0);
  EXPECT_EQ(a.sign, +1);
  // The first voxel inside is at index ceil(23.5 - 15) = 9 from the face.
  EXPECT_NEAR(a.air_m, 9e-3, 1e-12);
}

}  // namespace
}  // namespace isotouch::run
