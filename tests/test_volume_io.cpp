// Loaders on the shared data formats and on broken files.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <fcntl.h>
#include <sys/stat.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <cstring>
#include <thread>
#include <fstream>
#include <limits>

#include "isotouch/tests/memory_limited_child.h"
#include "isotouch/io/volume_io.h"

using isotouch::io::load_volume;
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
  // Slice 0 is the top of the head: the header's direction says z runs inferior, and the
  // offset keeps the physical box [0, 138] mm along z.
  EXPECT_FALSE(v.direction_is_identity);
  EXPECT_EQ(v.direction, (std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, -1}));
  EXPECT_EQ(v.orientation(), "LPI");
  EXPECT_NEAR(v.index_to_physical({0, 0, 0}).z, 0.138, 1e-12);
  EXPECT_NEAR(v.index_to_physical({0, 0, 92}).z, 0.0, 1e-12);
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
  expect_error((d / "t.mhd").string(), "ElementDataFile 't.raw' holds 380928 bytes");
}

TEST(VolumeIo, TruncatedNrrd) {
  const fs::path d = temp_dir();
  write(d / "t.raw", std::string(1000, '\0'));
  write(d / "t.nhdr",
        "NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 103 94 161\nspacings: 1 1 1\n"
        "data file: t.raw\nendian: big\nencoding: raw\n");
  expect_error((d / "t.nhdr").string(), "voxel data truncated: field 'data file' = 't.raw' holds 1000 bytes");
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

// A folder is read as a DICOM series (test_dicom_series.cpp); data/ holds none.
TEST(VolumeIo, FolderWithoutDicomIsNotAVolume) {
  expect_error(kData, "no DICOM files: its one file (README.md) is not a DICOM image slice");
}

// ---- Broken MetaImage headers ("Input and coordinates") --------------------------
namespace {
// A 4 x 4 x 4 MET_SHORT volume: header `extra` lines + raw file of `raw_bytes` bytes.
fs::path small_mhd(const fs::path& d, const std::string& extra, std::size_t raw_bytes,
                   const std::string& dims = "4 4 4", const std::string& type = "MET_SHORT",
                   const std::string& spacing = "1 1 1") {
  std::string raw(raw_bytes, '\0');
  for (std::size_t i = 0; i < raw.size(); ++i) raw[i] = char(i % 7);
  write(d / "s.raw", raw);
  write(d / "s.mhd", "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n" +
                         extra + "ElementSpacing = " + spacing + "\nDimSize = " + dims +
                         "\nElementType = " + type + "\nElementDataFile = s.raw\n");
  return d / "s.mhd";
}
}  // namespace

TEST(VolumeIo, MetaImageExactSizeLoads) {
  const Volume v = load_volume(small_mhd(temp_dir(), "", 128).string());
  EXPECT_EQ(v.voxels.size(), 64u);
  EXPECT_EQ(v.voxels[1], float(2 | (3 << 8)));  // little-endian short from bytes 2, 3
}

TEST(VolumeIo, MetaImageOneByteShort) {
  expect_error(small_mhd(temp_dir(), "", 127).string(), "ElementDataFile 's.raw' holds 127 bytes");
}

TEST(VolumeIo, MetaImageTypeTooSmallForFile) {
  // MET_UCHAR declared over int16 data: twice the bytes the header asks for.
  expect_error(small_mhd(temp_dir(), "", 128, "4 4 4", "MET_UCHAR").string(),
               "ElementDataFile 's.raw' holds 128 bytes; DimSize 4 x 4 x 4 of ElementType MET_UCHAR");
}

TEST(VolumeIo, MetaImageHugeHeaderSize) {
  expect_error(small_mhd(temp_dir(), "HeaderSize = 1000000\n", 128).string(), "HeaderSize = 1000000");
}

TEST(VolumeIo, MetaImageHeaderSizeHonoured) {
  const Volume v = load_volume(small_mhd(temp_dir(), "HeaderSize = 2\n", 130).string());
  EXPECT_EQ(v.voxels[0], float(2 | (3 << 8)));  // skipped bytes 0, 1
}

TEST(VolumeIo, MetaImageNanSpacing) {
  expect_error(small_mhd(temp_dir(), "", 128, "4 4 4", "MET_SHORT", "nan 1 1").string(), "ElementSpacing");
  expect_error(small_mhd(temp_dir(), "", 128, "4 4 4", "MET_SHORT", "nan 1 1").string(),
               "'nan' is not a finite number");
  expect_error(small_mhd(temp_dir(), "", 128, "4 4 4", "MET_SHORT", "1 inf 1").string(), "ElementSpacing");
}

TEST(VolumeIo, MetaImageAbsurdSpacing) {
  // 1e300 mm: the extent would hang any march over the volume.
  expect_error(small_mhd(temp_dir(), "", 128, "4 4 4", "MET_SHORT", "1e300 1 1").string(),
               "ElementSpacing");
  expect_error(small_mhd(temp_dir(), "", 128, "4 4 4", "MET_SHORT", "4000 1 1").string(),
               "extent");
}

TEST(VolumeIo, MetaImageNegativeDims) {
  expect_error(small_mhd(temp_dir(), "", 128, "-64 4 4").string(), "DimSize");
  expect_error(small_mhd(temp_dir(), "", 128, "-64 4 4").string(), "-64");
}

TEST(VolumeIo, MetaImageMissingDataFile) {
  const fs::path d = temp_dir();
  const fs::path h = small_mhd(d, "", 128);
  fs::remove(d / "s.raw");
  expect_error(h.string(), "s.raw");
}

// ---- Orientation: physical = origin + D (spacing * index) ----------------------------------
TEST(VolumeIo, EngineNiftiPhysicalFrame) {
  // engine.nii.gz: sform_code 1, srow = [1 0 0 -127; 0 1 0 -127; 0 0 1 -64] in RAS (read from
  // its header with Python). ITK's physical frame is LPS: x_LPS = -x_RAS, y_LPS = -y_RAS.
  const Volume v = load_volume(kData + "/ct-engine/engine.nii.gz");
  EXPECT_FALSE(v.direction_is_identity);
  EXPECT_EQ(v.orientation(), "RAS");
  for (const auto& idx : {isotouch::core::Vec3{0, 0, 0}, isotouch::core::Vec3{10, 200, 77},
                          isotouch::core::Vec3{255, 255, 127}}) {
    const isotouch::core::Vec3 ras{idx.x - 127, idx.y - 127, idx.z - 64};  // mm, from srow
    const isotouch::core::Vec3 p = v.index_to_physical(idx);
    EXPECT_NEAR(p.x, -ras.x * 1e-3, 1e-9);
    EXPECT_NEAR(p.y, -ras.y * 1e-3, 1e-9);
    EXPECT_NEAR(p.z, ras.z * 1e-3, 1e-9);
    const isotouch::core::Vec3 g = v.to_grid(p);  // back to the servo's grid frame
    const isotouch::core::Vec3 gi = v.grid.to_index(g);
    EXPECT_NEAR(gi.x, idx.x, 1e-6);
    EXPECT_NEAR(gi.z, idx.z, 1e-6);
  }
}

TEST(VolumeIo, MetaImagePermutedDirection) {
  // MetaIO's TransformMatrix lists the direction of index axis 0, then 1, then 2:
  // axis 0 -> +y (P), axis 1 -> -x (R), axis 2 -> +z (S).
  const Volume v = load_volume(small_mhd(temp_dir(), "TransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = 10 20 30\n",
                                         4 * 4 * 4 * 2, "4 4 4", "MET_SHORT", "2 3 4")
                                   .string());
  EXPECT_EQ(v.orientation(), "PRS");
  // Voxel (1, 2, 3): spacing * index = (2, 6, 12) mm; D that = (-6, 2, 12) mm.
  const isotouch::core::Vec3 p = v.index_to_physical({1, 2, 3});
  EXPECT_NEAR(p.x, (10 - 6) * 1e-3, 1e-12);
  EXPECT_NEAR(p.y, (20 + 2) * 1e-3, 1e-12);
  EXPECT_NEAR(p.z, (30 + 12) * 1e-3, 1e-12);
  const isotouch::core::Vec3 f = v.direction_apply({1, 0, 0});
  EXPECT_NEAR(f.y, 1.0, 1e-12);
}

TEST(VolumeIo, IdentityIsLps) {
  const Volume v = load_volume(kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd");
  EXPECT_EQ(v.orientation(), "LPS");
  const isotouch::core::Vec3 p = v.index_to_physical({1, 1, 1});
  EXPECT_NEAR(p.x, -227.616e-3 + 1.6835938e-3, 1e-12);
}

TEST(VolumeIo, NonFiniteVoxelsCounted) {
  const fs::path d = temp_dir();
  std::string raw(8 * 4, '\0');
  const float vals[8] = {1.f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                         -std::numeric_limits<float>::infinity(), 5.f, 2.f, 3.f, 4.f};
  std::memcpy(raw.data(), vals, sizeof vals);
  write(d / "f.raw", raw);
  write(d / "f.mhd", "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
                     "DimSize = 2 2 2\nElementType = MET_FLOAT\nElementDataFile = f.raw\n");
  const Volume v = load_volume((d / "f.mhd").string());
  EXPECT_EQ(v.nan_voxels, 1u);
  EXPECT_EQ(v.inf_voxels, 2u);
  EXPECT_EQ(v.finite_voxels, 5u);
  EXPECT_EQ(v.min_value, 1.f);
  EXPECT_EQ(v.max_value, 5.f);
}

TEST(VolumeIo, MetaImageLocalDataSize) {
  // .mha: the data follow the header. Exact size loads; one byte short or twice the bytes
  // (MET_UCHAR over 16-bit data) is an error.
  const fs::path d = temp_dir();
  const std::string header = "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
                             "DimSize = 4 4 4\nElementType = MET_SHORT\nElementDataFile = LOCAL\n";
  std::string raw(128, '\0');
  raw[2] = 7;
  write(d / "ok.mha", header + raw);
  EXPECT_EQ(load_volume((d / "ok.mha").string()).voxels[1], 7.f);
  write(d / "short.mha", header + raw.substr(0, 127));
  expect_error((d / "short.mha").string(), "LOCAL: the data after the header hold 127 bytes");
  std::string uchar = header;
  uchar.replace(uchar.find("MET_SHORT"), 9, "MET_UCHAR");
  write(d / "uchar.mha", uchar + raw);
  expect_error((d / "uchar.mha").string(), "hold 128 bytes; DimSize 4 x 4 x 4 of ElementType MET_UCHAR");
}

// ---- Direction matrix and NRRD spacings (review findings) --------------------------
TEST(VolumeIo, MetaImageSingularDirection) {
  // All zeros put every point at the origin ("LLL", every trace point (0,0,0)).
  expect_error(small_mhd(temp_dir(), "TransformMatrix = 0 0 0 0 0 0 0 0 0\n", 128).string(),
               "field 'TransformMatrix' gives the direction matrix (columns: index axes) [[0, 0, 0], [0, 0, 0], [0, 0, 0]], "
               "which is not orthonormal (max |D^T D - I| = 1");
}

TEST(VolumeIo, MetaImageScalingDirection) {
  // A factor 2 on axis 0 would silently scale the volume.
  expect_error(small_mhd(temp_dir(), "TransformMatrix = 2 0 0 0 1 0 0 0 1\n", 128).string(),
               "field 'TransformMatrix' gives the direction matrix (columns: index axes) [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "
               "which is not orthonormal (max |D^T D - I| = 3");
  // Within the tolerance (rounded cosines as scanners write them) it loads.
  EXPECT_NO_THROW(load_volume(small_mhd(temp_dir(), "TransformMatrix = 1.0004 0 0 0 1 0 0 0 1\n", 128).string()));
}

TEST(VolumeIo, NrrdSkewedSpaceDirections) {
  // Unit but not perpendicular: axis 1 at 45 degrees to axis 0.
  const fs::path d = temp_dir();
  write(d / "t.raw", std::string(64 * 2, '\0'));
  write(d / "t.nhdr",
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspace: left-posterior-superior\n"
        "space directions: (1,0,0) (0.70710678,0.70710678,0) (0,0,1)\ndata file: t.raw\nendian: little\n"
        "encoding: raw\n");
  expect_error((d / "t.nhdr").string(), "field 'space directions' gives the direction matrix");
}

TEST(VolumeIo, NrrdNanSpacing) {
  // ITK and teem both read "nan" as 1 mm; the header must give a number.
  const fs::path d = temp_dir();
  write(d / "t.raw", std::string(64 * 2, '\0'));
  const std::string tail = "\ndata file: t.raw\nendian: little\nencoding: raw\n";
  write(d / "t.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: nan 1 1" + tail);
  expect_error((d / "t.nhdr").string(), "field 'spacings' along axis 0 is 'nan' (must be a positive number of mm");
  write(d / "t.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: 1 -2 1" + tail);
  expect_error((d / "t.nhdr").string(), "field 'spacings' along axis 1 is '-2'");
  write(d / "t.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: 0.5 1 2" + tail);
  const Volume v = load_volume((d / "t.nhdr").string());
  EXPECT_DOUBLE_EQ(v.grid.spacing_m.x, 0.5e-3);
  EXPECT_DOUBLE_EQ(v.grid.spacing_m.z, 2e-3);
}

// ---- headers that promise more than the file holds: refused before anything is allocated

namespace {
/// load_volume(path) in a child process whose address space is capped at `limit` bytes: the
/// VolumeError message, or "std::bad_alloc" when the load tried to allocate what the header
/// promised.
std::string error_under_memory_limit(const std::string& path, std::uint64_t limit) {
  return isotouch::test::message_under_memory_limit(limit, [&] { (void)load_volume(path); });
}

/// A NIfTI-1 header (348 bytes + 4 of extension flag) for dims^3 float32 voxels, no data.
std::string nifti_header(std::int16_t dim) {
  std::string h(352, '\0');
  auto put = [&h](std::size_t at, const void* p, std::size_t n) { std::memcpy(h.data() + at, p, n); };
  const std::int32_t sizeof_hdr = 348;
  put(0, &sizeof_hdr, 4);
  const std::int16_t dims[8] = {3, dim, dim, dim, 1, 1, 1, 1};
  put(40, dims, sizeof dims);
  const std::int16_t datatype = 16, bitpix = 32;  // float32
  put(70, &datatype, 2);
  put(72, &bitpix, 2);
  const float pixdim[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  put(76, pixdim, sizeof pixdim);
  const float vox_offset = 352;
  put(108, &vox_offset, 4);
  put(344, "n+1", 4);
  return h;
}
}  // namespace

TEST(VolumeIo, TinyNiftiGzPromisingGigabytesIsRefusedBeforeAllocating) {
  const fs::path d = temp_dir();
  const std::string p = (d / "tiny.nii.gz").string();
  gzFile gz = gzopen(p.c_str(), "wb");
  ASSERT_TRUE(gz);
  const std::string h = nifti_header(1024);  // 1024^3 float32 = 4 GiB promised
  gzwrite(gz, h.data(), unsigned(h.size()));
  gzclose(gz);
  ASSERT_LT(fs::file_size(p), 1000u);
  const std::string m = error_under_memory_limit(p, std::uint64_t(1) << 30);
  EXPECT_NE(m.find("voxel data truncated"), std::string::npos) << m;
  EXPECT_NE(m.find(p), std::string::npos) << m;
}

TEST(VolumeIo, TinyRawNrrdPromisingGigabytesIsRefusedBeforeAllocating) {
  const fs::path d = temp_dir();
  const std::string p = (d / "tiny.nrrd").string();
  write(p, "NRRD0004\ntype: float\ndimension: 3\nsizes: 1024 1024 1024\nspacings: 1 1 1\nendian: little\n"
           "encoding: raw\n\n" + std::string(64, '\0'));
  const std::string m = error_under_memory_limit(p, std::uint64_t(1) << 30);
  EXPECT_NE(m.find("voxel data truncated"), std::string::npos) << m;
  EXPECT_NE(m.find("4294967296"), std::string::npos) << m;
}

TEST(VolumeIo, MoreThanTheMachineHoldsIsRefusedNamingTheMemory) {
  // 2^31 doubles + the float copy need 24 GiB; the file holds them (a sparse file), the
  // process may use 1 GiB (RLIMIT_AS): refused naming the memory, before anything is read.
  const fs::path d = temp_dir();
  const std::string p = (d / "big.nrrd").string();
  const std::string header = "NRRD0004\ntype: double\ndimension: 3\nsizes: 2048 1024 1024\nspacings: 0.01 0.01 0.01\n"
                             "endian: little\nencoding: raw\n\n";
  write(p, header);
  fs::resize_file(p, header.size() + (std::uint64_t(16) << 30));
  const std::string m = error_under_memory_limit(p, std::uint64_t(1) << 30);
  fs::remove(p);
  EXPECT_NE(m.find("2048 x 1024 x 1024 voxels of double need 24576 MiB"), std::string::npos) << m;
  EXPECT_NE(m.find("more than 3/4 of the 1024 MiB of memory this process may use"), std::string::npos) << m;
}

namespace {
/// `bytes` zero bytes compressed by zlib.
std::string zlib_zeros(std::size_t bytes) {
  const std::string zeros(bytes, '\0');
  uLongf n = compressBound(uLong(bytes));
  std::string z(n, '\0');
  compress2(reinterpret_cast<Bytef*>(z.data()), &n, reinterpret_cast<const Bytef*>(zeros.data()), uLong(bytes), 9);
  z.resize(n);
  return z;
}
}  // namespace

// Compressed data are inflated and counted before the voxels are allocated: a few-byte
// file promising 2 GiB is refused under a 1 GiB address-space limit with the counts.
TEST(VolumeIo, TinyCompressedMetaImagePromisingGigabytesIsRefusedBeforeAllocating) {
  const fs::path d = temp_dir();
  const std::string z = zlib_zeros(100);
  write(d / "c.zraw", z);
  const std::string p = (d / "c.mhd").string();
  write(p, "ObjectType = Image\nNDims = 3\nBinaryData = True\nCompressedData = True\nCompressedDataSize = " +
               std::to_string(z.size()) + "\nElementSpacing = 0.001 0.001 0.001\nDimSize = 2048 1024 1024\n"
               "ElementType = MET_UCHAR\nElementDataFile = c.zraw\n");
  const std::string m = error_under_memory_limit(p, std::uint64_t(1) << 30);
  EXPECT_NE(m.find(p + ": voxel data truncated: the compressed data of field 'ElementDataFile' = 'c.zraw' inflate "
                       "to 100 bytes, the header promises 2147483648"), std::string::npos) << m;
}

TEST(VolumeIo, TinyGzipNrrdPromisingGigabytesIsRefusedBeforeAllocating) {
  const fs::path d = temp_dir();
  const std::string p = (d / "tiny.nrrd").string();
  write(p, "NRRD0004\ntype: float\ndimension: 3\nsizes: 1024 1024 1024\nspacings: 0.001 0.001 0.001\n"
           "endian: little\nencoding: gzip\n\n" + zlib_zeros(64));
  const std::string m = error_under_memory_limit(p, std::uint64_t(1) << 30);
  EXPECT_NE(m.find(p + ": voxel data truncated: the compressed data of the data after the header inflate to 64 "
                       "bytes, the header promises 4294967296"), std::string::npos) << m;
}

namespace {
/// load_volume(path) while a thread unblocks a reader of the FIFO at `fifo` (opening it for
/// writing, then closing it): the message, and whether the FIFO was ever opened.
std::string load_error_beside_fifo(const std::string& path, const std::string& fifo, bool& opened) {
  std::atomic<bool> done{false}, was_opened{false};
  std::thread writer([&] {
    while (!done) {
      const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);  // ENXIO while nobody reads
      if (fd >= 0) {
        was_opened = true;
        ::close(fd);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  std::string m = "loaded";
  try {
    (void)load_volume(path);
  } catch (const std::exception& e) {
    m = e.what();
  }
  done = true;
  writer.join();
  opened = was_opened;
  return m;
}
}  // namespace

// A FIFO named as a volume (or as its data file) is refused before open(), which would
// block until a writer came.
TEST(VolumeIo, FifoIsRefusedBeforeItIsOpened) {
  const fs::path d = temp_dir();
  const std::string f = (d / "f.mhd").string();
  fs::remove(f);
  ASSERT_EQ(::mkfifo(f.c_str(), 0600), 0);
  bool opened = false;
  std::string m = load_error_beside_fifo(f, f, opened);
  EXPECT_EQ(m, f + ": not a regular file (a FIFO): a volume is read from a regular file or a DICOM series folder");
  EXPECT_FALSE(opened) << "the loader opened the FIFO";
  const std::string raw = (d / "fifo.raw").string();
  fs::remove(raw);
  ASSERT_EQ(::mkfifo(raw.c_str(), 0600), 0);
  write(d / "h.mhd", "ObjectType = Image\nNDims = 3\nElementSpacing = 1 1 1\nDimSize = 4 4 4\n"
                     "ElementType = MET_SHORT\nElementDataFile = fifo.raw\n");
  m = load_error_beside_fifo((d / "h.mhd").string(), raw, opened);
  EXPECT_EQ(m, raw + ": not a regular file (a FIFO): the voxel data of " + (d / "h.mhd").string() +
                   " (field 'ElementDataFile') must be a regular file");
  EXPECT_FALSE(opened) << "the loader opened the FIFO";
}
