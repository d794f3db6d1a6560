// Loaders on the shared data formats and on broken files.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "volume_io.h"

using isotouch::engine::load_volume;
using isotouch::engine::Volume;
using isotouch::engine::VolumeError;
namespace fs = std::filesystem;

namespace {
const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kHead = kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd";

fs::path temp_dir() {
  fs::path d = fs::temp_directory_path() /
               ("isotouch_io_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
                "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  fs::create_directories(d);
  return d;
}
void write(const fs::path& p, const std::string& s) { std::ofstream(p, std::ios::binary) << s; }

// Expect a VolumeError whose message names the file and contains `what`.
void expect_error(const std::string& path, const std::string& what) {
  try {
    load_volume(path);
    FAIL() << "no error for " << path;
  } catch (const VolumeError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(path), std::string::npos) << m;
    EXPECT_NE(m.find(what), std::string::npos) << "expected '" << what << "' in: " << m;
  }
}
}  // namespace

TEST(VolumeIo, HeadMetaImage) {
  const Volume v = load_volume(kHead);
  EXPECT_EQ(v.grid.dims, (std::array<int, 3>{64, 64, 93}));
  EXPECT_DOUBLE_EQ(v.grid.spacing_m.x, 3.2e-3);
  EXPECT_DOUBLE_EQ(v.grid.spacing_m.z, 1.5e-3);
  EXPECT_EQ(v.component_type, "short");
  EXPECT_EQ(v.min_value, 0.f);
  EXPECT_EQ(v.max_value, 3926.f);  // the README: values 0-3926
  EXPECT_TRUE(v.direction_is_identity);
}

TEST(VolumeIo, HeadMultiFileNrrdMatchesMetaImage) {
  // quarter.nhdr: `data file: quarter.%d 1 93 1` and the off-spec spacings+space.
  const Volume a = load_volume(kHead);
  const Volume b = load_volume(kData + "/ct-head-headsq/original/quarter.nhdr");
  EXPECT_EQ(b.grid.dims, a.grid.dims);
  EXPECT_DOUBLE_EQ(b.grid.spacing_m.x, a.grid.spacing_m.x);
  EXPECT_DOUBLE_EQ(b.grid.spacing_m.z, a.grid.spacing_m.z);
  ASSERT_EQ(a.voxels.size(), b.voxels.size());
  EXPECT_TRUE(a.voxels == b.voxels);
}

TEST(VolumeIo, ToothBigEndianNrrdMatchesMetaImage) {
  const Volume a = load_volume(kData + "/ct-tooth/tooth.nhdr");
  const Volume b = load_volume(kData + "/ct-tooth/tooth.mhd");
  EXPECT_EQ(a.grid.dims, (std::array<int, 3>{103, 94, 161}));
  EXPECT_EQ(a.component_type, "unsigned_short");
  EXPECT_TRUE(a.voxels == b.voxels);
  // Big-endian decoded right: values are plausible CT numbers, not byte-swapped noise.
  EXPECT_GT(a.max_value, 1000.f);
  EXPECT_LT(a.max_value, 5000.f);
}

TEST(VolumeIo, ChestHounsfield) {
  const Volume v = load_volume(kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd");
  EXPECT_EQ(v.grid.dims, (std::array<int, 3>{256, 256, 64}));
  EXPECT_NEAR(v.grid.origin_m.x, -0.227616, 1e-9);
  EXPECT_NEAR(v.grid.origin_m.z, -0.439, 1e-9);
  EXPECT_NEAR(v.grid.spacing_m.x, 1.6835938e-3, 1e-12);
  EXPECT_LE(v.min_value, -1000.f);  // air in HU
  EXPECT_GT(v.max_value, 500.f);    // bone
}

TEST(VolumeIo, EngineNiftiGz) {
  const Volume v = load_volume(kData + "/ct-engine/engine.nii.gz");
  EXPECT_EQ(v.grid.dims, (std::array<int, 3>{256, 256, 128}));
  EXPECT_EQ(v.component_type, "unsigned_char");
  EXPECT_GT(v.max_value, 100.f);
  EXPECT_EQ(v.nan_voxels, 0u);
}

TEST(VolumeIo, MissingFile) { expect_error("/nonexistent/volume.mhd", "no such file"); }

TEST(VolumeIo, NotAVolume) {
  const fs::path p = temp_dir() / "notes.txt";
  write(p, "hello\n");
  expect_error(p.string(), "not a readable");
}

TEST(VolumeIo, TruncatedMetaImage) {
  const fs::path d = temp_dir();
  std::ifstream raw(kData + "/ct-head-headsq/headsq_64x64x93_int16.raw", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(raw)), {});
  write(d / "t.raw", bytes.substr(0, bytes.size() / 2));
  write(d / "t.mhd",
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
        "ElementSpacing = 3.2 3.2 1.5\nDimSize = 64 64 93\nElementType = MET_SHORT\nElementDataFile = t.raw\n");
  expect_error((d / "t.mhd").string(), "voxel data truncated");
}

TEST(VolumeIo, TruncatedNrrd) {
  const fs::path d = temp_dir();
  write(d / "t.raw", std::string(1000, '\0'));
  write(d / "t.nhdr",
        "NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 103 94 161\nspacings: 1 1 1\n"
        "data file: t.raw\nendian: big\nencoding: raw\n");
  expect_error((d / "t.nhdr").string(), "fread got only");
}

TEST(VolumeIo, TruncatedNiftiGz) {
  const fs::path d = temp_dir();
  std::ifstream in(kData + "/ct-engine/engine.nii.gz", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), {});
  write(d / "t.nii.gz", bytes.substr(0, bytes.size() / 3));
  expect_error((d / "t.nii.gz").string(), "voxel data truncated");
}

TEST(VolumeIo, UnknownType) {
  const fs::path d = temp_dir();
  write(d / "t.raw", std::string(8, '\0'));
  write(d / "t.mhd",
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nDimSize = 2 2 2\nElementType = MET_FOO\n"
        "ElementDataFile = t.raw\n");
  expect_error((d / "t.mhd").string(), "unknown or unsupported voxel type");
}

TEST(VolumeIo, AbsurdDimensions) {
  const fs::path d = temp_dir();
  write(d / "t.raw", std::string(8, '\0'));
  write(d / "t.mhd",
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nDimSize = 100000 100000 100000\n"
        "ElementType = MET_SHORT\nElementDataFile = t.raw\n");
  expect_error((d / "t.mhd").string(), "absurd dimensions");
}

TEST(VolumeIo, DirectoryIsNotAVolume) { expect_error(kData, "is a directory"); }
