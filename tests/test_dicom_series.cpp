// DICOM series folders: the shipped chest series against the shipped MetaImage of the same
// patient (converted from these slices outside isotouch: HU, then a 2x2 in-plane mean), and
// broken copies of the series (a slice removed, a size, a position or a series UID changed
// in one file's header, a truncated file, an empty folder, non-DICOM files).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

#include "isotouch/io/dicom_series.h"
#include "isotouch/tests/temp_dir.h"
#include "isotouch/io/volume_io.h"

using isotouch::engine::Volume;
using isotouch::engine::VolumeError;
using isotouch::io::DicomSeriesInfo;
using isotouch::io::load_dicom_series;
using isotouch::io::load_volume;
using isotouch::test::TempDir;
namespace fs = std::filesystem;

namespace {
const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kSeries = kData + "/ct-chest-lungdx-a0001/dicom-5mm";
const std::string kMeta = kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd";

// The HU of the MetaImage are the 2x2 means of the slices' HU, rounded to int16 (the README:
// "HU = stored - 1024, then 2x2 in-plane mean"): a mean of four integers is a multiple of
// 0.25, and rounding moves it by at most 0.5. Measured: max |mean - MetaImage| = 0.5 HU,
// mean 0.22 HU, with 0 voxels beyond 0.5 HU (of 4194304).
constexpr double kRoundingHu = 0.5;

// A copy of the shipped series in a temp folder (without `leave_out`), for breaking.
struct SeriesCopy {
  TempDir dir{"isotouch-dicom"};
  explicit SeriesCopy(const std::string& leave_out = "") {
    for (const auto& e : fs::directory_iterator(kSeries))
      if (e.path().filename() != leave_out) fs::copy_file(e.path(), dir.path / e.path().filename());
  }
  std::string path() const { return dir.path.string(); }
  // Replace the first `from` in FILE's bytes after `start` by `to` (same length).
  void patch(const std::string& file, const std::string& from, const std::string& to, std::size_t start = 0) const {
    ASSERT_EQ(from.size(), to.size());
    std::string b = isotouch::test::slurp(dir.path / file);
    const auto at = b.find(from, start);
    ASSERT_NE(at, std::string::npos) << file << ": bytes to patch not found";
    b.replace(at, to.size(), to);
    std::ofstream(dir.path / file, std::ios::binary) << b;
  }
};

// The SeriesInstanceUID (0020,000E) of a file (implicit VR little endian): the first
// element with that tag whose value is a UID.
std::pair<std::size_t, std::string> series_uid_of(const fs::path& file) {
  const std::string b = isotouch::test::slurp(file);
  const std::string tag("\x20\x00\x0e\x00", 4);
  for (std::size_t at = b.find(tag); at != std::string::npos; at = b.find(tag, at + 1)) {
    std::uint32_t len = 0;
    std::memcpy(&len, b.data() + at + 4, 4);
    if (len == 0 || len > 64) continue;
    std::string v = b.substr(at + 8, len);
    while (!v.empty() && v.back() == '\0') v.pop_back();
    if (!v.empty() && v.find_first_not_of("0123456789.") == std::string::npos) return {at + 8, v};
  }
  return {0, ""};
}

// Expect a VolumeError naming the folder and containing each of `what`.
void expect_error(const std::string& folder, std::initializer_list<std::string> what) {
  try {
    load_volume(folder);
    ADD_FAILURE() << "no error for " << folder;
  } catch (const VolumeError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind(folder + ": ", 0), 0u) << "the message must start with the folder: " << m;
    for (const auto& w : what) EXPECT_NE(m.find(w), std::string::npos) << "expected '" << w << "' in: " << m;
  }
}
}  // namespace

TEST(DicomSeries, ChestMatchesTheMetaImageWithinRounding) {
  const auto t0 = std::chrono::steady_clock::now();
  DicomSeriesInfo info;
  const Volume d = load_dicom_series(kSeries, "", &info);
  const double load_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const Volume m = load_volume(kMeta);
  std::cout << "[ measure  ] load_dicom_series " << kSeries << ": " << load_ms << " ms\n";

  EXPECT_EQ(d.grid.dims, (std::array<int, 3>{512, 512, 64}));
  EXPECT_EQ(d.reader, "itk:GDCMImageIO");
  EXPECT_EQ(d.path, kSeries);
  EXPECT_EQ(info.files.size(), 64u);
  EXPECT_EQ(info.series_in_folder, 1u);
  EXPECT_TRUE(info.notes.empty()) << info.notes.front();
  EXPECT_EQ(info.description.rfind("CT", 0), 0u) << info.description;
  // Index z runs up the normal (+z, S): the first slice is the lowest, 1-64.dcm at -439 mm.
  EXPECT_EQ(fs::path(info.files.front()).filename(), "1-64.dcm");
  EXPECT_EQ(fs::path(info.files.back()).filename(), "1-01.dcm");

  // Orientation and spacing: the MetaImage's voxels are 2x2 blocks of the slices' pixels,
  // centred half a slice pixel further along x and y.
  EXPECT_EQ(d.orientation(), m.orientation());
  EXPECT_EQ(d.orientation(), "LPS");
  EXPECT_TRUE(d.direction_is_identity);
  EXPECT_NEAR(2 * d.grid.spacing_m.x, m.grid.spacing_m.x, 1e-9);
  EXPECT_NEAR(2 * d.grid.spacing_m.y, m.grid.spacing_m.y, 1e-9);
  EXPECT_NEAR(d.grid.spacing_m.z, m.grid.spacing_m.z, 1e-9);
  EXPECT_NEAR(d.grid.spacing_m.z, 5e-3, 1e-12);
  EXPECT_NEAR(d.grid.origin_m.x + d.grid.spacing_m.x / 2, m.grid.origin_m.x, 1e-6);  // 1 um: the .mhd's digits
  EXPECT_NEAR(d.grid.origin_m.y + d.grid.spacing_m.y / 2, m.grid.origin_m.y, 1e-6);
  EXPECT_NEAR(d.grid.origin_m.z, m.grid.origin_m.z, 1e-9);

  // Values: HU (the rescale applied), the 2x2 means equal to the MetaImage's within rounding.
  double max_diff = 0, sum_diff = 0;
  std::size_t beyond = 0, n = 0;
  for (int z = 0; z < 64; ++z)
    for (int y = 0; y < 256; ++y)
      for (int x = 0; x < 256; ++x) {
        double s = 0;
        for (int j = 0; j < 2; ++j)
          for (int i = 0; i < 2; ++i) s += d.voxels[d.grid.index(2 * x + i, 2 * y + j, z)];
        const double diff = std::abs(s / 4 - double(m.voxels[m.grid.index(x, y, z)]));
        max_diff = std::max(max_diff, diff);
        sum_diff += diff;
        beyond += diff > kRoundingHu;
        ++n;
      }
  std::cout << "[ measure  ] 2x2 mean vs MetaImage: max |diff| " << max_diff << " HU, mean " << sum_diff / double(n)
            << " HU, beyond " << kRoundingHu << " HU: " << beyond << " of " << n << "\n";
  EXPECT_LE(max_diff, kRoundingHu);
  EXPECT_EQ(beyond, 0u);
  EXPECT_GT(sum_diff / double(n), 0.0);  // the MetaImage did round: not the same data twice
  EXPECT_EQ(d.min_value, -1024.f);       // stored 0 - 1024: the rescale is applied
  EXPECT_GT(d.max_value, 1000.f);        // bone
}

TEST(DicomSeries, LoadVolumeReadsAFolderAsASeries) {
  const Volume a = load_volume(kSeries);
  const Volume b = load_dicom_series(kSeries);
  EXPECT_EQ(a.grid.dims, b.grid.dims);
  EXPECT_EQ(a.voxels, b.voxels);
  EXPECT_EQ(a.reader, "itk:GDCMImageIO");
}

TEST(DicomSeries, EmptyFolder) {
  TempDir dir("isotouch-dicom-empty");
  expect_error(dir.path.string(), {"no DICOM files", "holds no files"});
}

TEST(DicomSeries, FolderOfNonDicomFiles) {
  TempDir dir("isotouch-dicom-none");
  std::ofstream(dir.path / "notes.txt") << "not DICOM\n";
  fs::copy_file(kMeta, dir.path / "chest.mhd");
  expect_error(dir.path.string(), {"no DICOM files", "none of its 2 files", "chest.mhd", "notes.txt"});
}

TEST(DicomSeries, MissingFolder) {
  expect_error(kData + "/no-such-folder/", {"no such"});
}

TEST(DicomSeries, SliceMissingFromTheMiddle) {
  const SeriesCopy c("1-33.dcm");  // at -284 mm, between 1-34.dcm (-289) and 1-32.dcm (-279)
  expect_error(c.path(), {"a slice is missing between 1-34.dcm (at -289 mm) and 1-32.dcm (at -279 mm)",
                          "10 mm apart", "5 mm"});
}

TEST(DicomSeries, UnevenSpacing) {
  const SeriesCopy c;
  c.patch("1-33.dcm", "\\-284 ", "\\-285 ");  // ImagePositionPatient z, same length
  expect_error(c.path(), {"uneven slice spacing", "1-34.dcm (at -289 mm) and 1-33.dcm (at -285 mm)", "4 mm apart"});
}

TEST(DicomSeries, TwoSlicesAtOnePosition) {
  const SeriesCopy c;
  c.patch("1-33.dcm", "\\-284 ", "\\-289 ");  // where 1-34.dcm is
  expect_error(c.path(), {"two slices at one position", "1-33.dcm", "1-34.dcm"});
}

TEST(DicomSeries, SlicesOfDifferentSize) {
  const SeriesCopy c;
  // Rows (0028,0010) = 512 -> 256 in one file (implicit VR little endian: tag, length 2, value).
  c.patch("1-10.dcm", std::string("\x28\x00\x10\x00\x02\x00\x00\x00\x00\x02", 10),
          std::string("\x28\x00\x10\x00\x02\x00\x00\x00\x00\x01", 10));
  expect_error(c.path(), {"the slices differ in size", "is 512 x 512", "1-10.dcm is 512 x 256", "(Columns x Rows)"});
}

TEST(DicomSeries, TruncatedFileIsNamed) {
  const SeriesCopy c;
  fs::resize_file(c.dir.path / "1-40.dcm", 200000);  // the header whole, half the pixels
  expect_error(c.path(), {"1-40.dcm is truncated: its Pixel Data (7FE0,0010) is 524288 bytes, the file holds"});
}

TEST(DicomSeries, SeveralSeriesTakeTheLargestOrTheNamedOne) {
  const SeriesCopy c;
  // The ten lowest slices (1-55 .. 1-64) get another SeriesInstanceUID.
  const auto [at, uid] = series_uid_of(c.dir.path / "1-60.dcm");
  ASSERT_FALSE(uid.empty());
  std::string other = uid;
  other.back() = other.back() == '9' ? '8' : char(other.back() + 1);
  for (int i = 55; i <= 64; ++i) c.patch("1-" + std::to_string(i) + ".dcm", uid, other, at - 8);

  DicomSeriesInfo info;
  const Volume big = load_dicom_series(c.path(), "", &info);
  EXPECT_EQ(big.grid.dims[2], 54);
  EXPECT_EQ(info.series_uid, uid);
  EXPECT_EQ(info.series_in_folder, 2u);
  ASSERT_EQ(info.notes.size(), 1u);
  EXPECT_NE(info.notes[0].find("2 DICOM series; read " + uid + " (54 files, the most), not " + other + " (10 files)"),
            std::string::npos)
      << info.notes[0];

  const Volume small = load_dicom_series(c.path(), other, &info);
  EXPECT_EQ(small.grid.dims[2], 10);
  EXPECT_EQ(info.series_uid, other);
  EXPECT_NEAR(small.grid.origin_m.z, -0.439, 1e-9);

  try {
    load_dicom_series(c.path(), "1.2.3");
    ADD_FAILURE() << "an absent series UID was accepted";
  } catch (const VolumeError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("no DICOM series with SeriesInstanceUID 1.2.3"), std::string::npos) << m;
    EXPECT_NE(m.find(uid + " (54 files)"), std::string::npos) << m;
    EXPECT_NE(m.find(other + " (10 files)"), std::string::npos) << m;
  }
}

TEST(DicomSeries, NonDicomFilesBesideTheSlicesAreIgnoredWithANote) {
  const SeriesCopy c;
  std::ofstream(c.dir.path / "README.txt") << "slices of the chest\n";
  DicomSeriesInfo info;
  const Volume v = load_dicom_series(c.path(), "", &info);
  EXPECT_EQ(v.grid.dims[2], 64);
  ASSERT_EQ(info.notes.size(), 1u);
  EXPECT_NE(info.notes[0].find("ignored 1 file that is not a DICOM image slice: README.txt"), std::string::npos)
      << info.notes[0];
}
