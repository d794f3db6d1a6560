// Volumes written through ITK (.mha, .nrrd, .nii, .nii.gz) read back by io::load_volume
// with every voxel bit for bit, the spacing, origin and a rotated direction.
#include <unistd.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/io/volume_write.h"

namespace fs = std::filesystem;
using namespace isotouch;

namespace {
fs::path temp_dir() {
  std::string t = (fs::temp_directory_path() / "isotouch-volume-write-XXXXXX").string();
  return ::mkdtemp(t.data());
}
}  // namespace

TEST(VolumeWrite, EveryFormatRoundTripsVoxelsSpacingOriginDirection) {
  const fs::path dir = temp_dir();
  engine::Volume v = engine::make_random({13, 7, 5}, {0.7e-3, 0.5e-3, 1.3e-3}, -5.0f, 7.0f, 99);
  v.grid.origin_m = {-0.0123, 0.0456, 0.0015};
  v.voxels[1] = -0.0f;
  v.voxels[2] = std::numeric_limits<float>::denorm_min();
  v.direction = {0, 0, 1, 1, 0, 0, 0, 1, 0};  // axes permuted (a rotation)
  v.direction_is_identity = false;
  v.update_stats();
  for (const std::string ext : {".mha", ".nrrd", ".nii", ".nii.gz"}) {
    SCOPED_TRACE(ext);
    const std::string path = (dir / ("v" + ext)).string();
    io::save_volume_itk(v, path);
    const engine::Volume back = io::load_volume(path);
    ASSERT_EQ(back.grid.dims, v.grid.dims);
    EXPECT_EQ(std::memcmp(back.voxels.data(), v.voxels.data(), v.voxels.size() * sizeof(float)), 0) << "voxels differ";
    EXPECT_NEAR(back.grid.spacing_m.x, v.grid.spacing_m.x, 1e-10);  // NIfTI stores float32
    EXPECT_NEAR(back.grid.spacing_m.z, v.grid.spacing_m.z, 1e-10);
    EXPECT_NEAR(back.grid.origin_m.x, v.grid.origin_m.x, 1e-8);
    EXPECT_NEAR(back.grid.origin_m.y, v.grid.origin_m.y, 1e-8);
    for (int i = 0; i < 9; ++i) EXPECT_NEAR(back.direction[std::size_t(i)], v.direction[std::size_t(i)], 1e-6) << i;
  }
  fs::remove_all(dir);
}

TEST(VolumeWrite, BadNamesAreRefusedAndNothingIsWritten) {
  const fs::path dir = temp_dir();
  const engine::Volume v = engine::make_sphere({8, 8, 8}, 1e-3, 3);
  for (const std::string name : {"v.mhd", "v.png", "v"}) {
    try {
      io::save_volume_itk(v, (dir / name).string());
      ADD_FAILURE() << name << " was accepted";
    } catch (const engine::VolumeError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(fs::is_empty(dir));
  fs::remove_all(dir);
}
