// The isovalue a volume opens at without --iso (engine/iso_choice, io/scan): Otsu's
// thresholds on histograms whose answer is known, the CT-in-HU rule, a stored isovalue, and
// the shipped volumes' rules (their values are checked against an independent computation in
// cli_scan.py).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "isotouch/engine/iso_choice.h"
#include "isotouch/io/scan.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/tests/temp_dir.h"

namespace isotouch {
namespace {
namespace fs = std::filesystem;
using engine::Volume;

const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kHead = kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd";

/// A volume holding `values` (any dims: only the histogram matters).
Volume volume_of(const std::vector<float>& values) {
  Volume v;
  v.grid.dims = {int(values.size()), 1, 1};
  v.voxels = values;
  v.update_stats();
  return v;
}

/// n voxels evenly over [a, b).
void add_uniform(std::vector<float>& out, double a, double b, int n) {
  for (int i = 0; i < n; ++i) out.push_back(float(a + (b - a) * (i + 0.5) / n));
}

TEST(Histogram, CountsEveryFiniteVoxelInItsBin) {
  const Volume v = volume_of({0, 1, 2, 3, NAN, INFINITY, 4});
  const engine::Histogram h = engine::histogram(v, 4);
  ASSERT_EQ(h.counts.size(), 4u);
  EXPECT_EQ(h.lo, 0);
  EXPECT_EQ(h.hi, 4);
  // Bins [0,1) [1,2) [2,3) [3,4]: the maximum falls in the last one.
  EXPECT_EQ(h.counts, (std::vector<std::uint64_t>{1, 1, 1, 2}));
}

TEST(Otsu, TwoEqualSeparatedClassesSplitInTheGap) {
  std::vector<float> x;
  add_uniform(x, 0, 100, 5000);
  add_uniform(x, 300, 400, 5000);
  const auto t = engine::otsu_thresholds(engine::histogram(volume_of(x), 256), 2);
  ASSERT_EQ(t.size(), 1u);
  // Any split in the empty gap (100, 300] gives the same variance; the first is taken.
  EXPECT_GT(t[0], 100);
  EXPECT_LE(t[0], 300);
}

TEST(Otsu, ThreeClassesSplitInBothGapsWhereTwoClassesMergeTwo) {
  // Air (half the voxels), soft tissue, a small dense class: a two-class split falls
  // between air and the rest; the three-class upper threshold isolates the dense class.
  std::vector<float> x;
  add_uniform(x, 0, 50, 50000);
  add_uniform(x, 500, 700, 40000);
  add_uniform(x, 1200, 1600, 10000);
  const engine::Histogram h = engine::histogram(volume_of(x), 256);
  const auto t2 = engine::otsu_thresholds(h, 2);
  const auto t3 = engine::otsu_thresholds(h, 3);
  ASSERT_EQ(t2.size(), 1u);
  ASSERT_EQ(t3.size(), 2u);
  EXPECT_GE(t2[0], 49.99);  // the first edge above the class's largest value, 49.9995
  EXPECT_LE(t2[0], 500);
  EXPECT_GE(t3[0], 49.99);
  EXPECT_LE(t3[0], 500);
  EXPECT_GT(t3[1], 700);
  EXPECT_LE(t3[1], 1200);
}

TEST(Otsu, MatchesBruteForceOnAnUnevenHistogram) {
  // Overlapping classes: the exhaustive search over every (t1, t2) written out here.
  engine::Histogram h;
  h.lo = 0;
  h.hi = 20;
  h.counts = {5, 9, 14, 7, 3, 2, 6, 11, 13, 8, 4, 1, 1, 2, 5, 9, 6, 3, 1, 0};
  double best = -1;
  std::size_t b1 = 0, b2 = 0;
  for (std::size_t t1 = 1; t1 < 20; ++t1)
    for (std::size_t t2 = t1 + 1; t2 < 20; ++t2) {
      double v = 0;
      for (auto [a, b] : {std::pair{std::size_t(0), t1}, std::pair{t1, t2}, std::pair{t2, std::size_t(20)}}) {
        double n = 0, s = 0;
        for (std::size_t i = a; i < b; ++i) n += double(h.counts[i]), s += double(h.counts[i]) * (double(i) + 0.5);
        if (n > 0) v += s * s / n;
      }
      if (v > best) best = v, b1 = t1, b2 = t2;
    }
  const auto t = engine::otsu_thresholds(h, 3);
  ASSERT_EQ(t.size(), 2u);
  EXPECT_EQ(t[0], double(b1));
  EXPECT_EQ(t[1], double(b2));
}

TEST(ChooseIsovalue, StoredIsovalueWins) {
  engine::VolumeHints hints;
  hints.stored = core::Isosurface{42.5, core::InsideIs::kBelow};
  hints.stored_from = ".vdb metadata";
  hints.modality = "CT";
  const auto c = engine::choose_isovalue(volume_of({-1024, 0, 1000}), hints);
  EXPECT_EQ(c.iso.tau, 42.5);
  EXPECT_EQ(c.iso.inside, core::InsideIs::kBelow);
  EXPECT_NE(c.rule.find("stored in the file (.vdb metadata)"), std::string::npos) << c.rule;
}

TEST(ChooseIsovalue, CtInHuOpensAtTheBonePreset) {
  // Recognised by the minimum (air, -1024 HU) alone.
  const auto c = engine::choose_isovalue(volume_of({-1024, -700, 40, 60, 700}), {});
  EXPECT_TRUE(c.hounsfield);
  EXPECT_EQ(c.iso.tau, 300);
  EXPECT_EQ(c.iso.inside, core::InsideIs::kAbove);
  EXPECT_NE(c.rule.find("CT in HU (minimum -1024"), std::string::npos) << c.rule;
  ASSERT_EQ(c.presets.size(), 3u);
  EXPECT_EQ(c.presets[0].name, "bone");
  for (const auto& p : c.presets) {
    EXPECT_LE(p.band_lo, p.value) << p.name;
    EXPECT_LE(p.value, p.band_hi) << p.name;
  }
  // Recognised by the modality although the minimum says nothing.
  engine::VolumeHints ct;
  ct.modality = "CT";
  const auto m = engine::choose_isovalue(volume_of({-200, 0, 1500}), ct);
  EXPECT_TRUE(m.hounsfield);
  EXPECT_NE(m.rule.find("modality CT"), std::string::npos) << m.rule;
  // Neither: an MR, or a CT in scanner units, goes to the histogram.
  engine::VolumeHints mr;
  mr.modality = "MR";
  EXPECT_FALSE(engine::choose_isovalue(volume_of({0, 10, 20}), mr).hounsfield);
  EXPECT_FALSE(engine::is_ct_hounsfield(volume_of({-1200, 0, 100}), ""));
}

/// A CT's histogram in HU without air's -1024 as its minimum (a resampled abdomen, whose
/// interpolation and padding reach -1207): air around -1000, soft tissue 0-60, a bone tail.
std::vector<float> resampled_ct_hu(double shift = 0) {
  std::vector<float> x;
  add_uniform(x, -1207 + shift, -1100 + shift, 200);
  add_uniform(x, -1040 + shift, -960 + shift, 30000);
  add_uniform(x, -120 + shift, -60 + shift, 8000);  // fat
  add_uniform(x, 0 + shift, 60 + shift, 50000);
  add_uniform(x, 300 + shift, 1400 + shift, 3000);
  return x;
}

TEST(ChooseIsovalue, ACtInHuWhoseMinimumIsNotAirIsRecognisedByItsHistogram) {
  const Volume v = volume_of(resampled_ct_hu());
  const auto c = engine::choose_isovalue(v, {});
  EXPECT_TRUE(c.hounsfield) << c.rule;  // (before: -24, the three-class Otsu between air and tissue)
  EXPECT_EQ(c.iso.tau, 300);
  EXPECT_EQ(c.presets.size(), 3u);
  EXPECT_NE(c.rule.find("histogram: air 32.9 % in -1100 to -850, soft tissue 63.6 %"), std::string::npos) << c.rule;
  // Not HU: the same scan in scanner units (shifted by +1024: no air band), an MR, or a
  // volume without a bone tail (a phantom of water and air) go to the histogram's Otsu.
  EXPECT_FALSE(engine::choose_isovalue(volume_of(resampled_ct_hu(1024)), {}).hounsfield);
  engine::VolumeHints mr;
  mr.modality = "MR";
  EXPECT_FALSE(engine::choose_isovalue(v, mr).hounsfield);
  std::vector<float> water;
  add_uniform(water, -1040, -960, 30000);
  add_uniform(water, -20, 20, 30000);
  water.push_back(-1207);
  EXPECT_EQ(engine::hu_by_histogram(volume_of(water)), "");
  // Padding below any scanner's (-3024) is not a CT's.
  std::vector<float> padded = resampled_ct_hu();
  padded.push_back(-5000);
  EXPECT_EQ(engine::hu_by_histogram(volume_of(padded)), "");
}

TEST(ChooseIsovalue, HeaderTextSaysCtOrHuWhereTheValuesAgree) {
  // A CT in HU cropped inside the body: no air band, minimum -600; only the header says it.
  std::vector<float> x;
  add_uniform(x, -600, -100, 1000);
  add_uniform(x, 0, 60, 5000);
  add_uniform(x, 300, 1200, 500);
  engine::VolumeHints h;
  io::read_text_hints("NIfTI", {{"descrip", "Abdomen CT, resampled 1 mm"}}, h);
  EXPECT_EQ(h.modality, "CT");
  EXPECT_EQ(h.modality_from, "NIfTI descrip 'Abdomen CT, resampled 1 mm'");
  const auto c = engine::choose_isovalue(volume_of(x), h);
  EXPECT_TRUE(c.hounsfield);
  EXPECT_NE(c.rule.find("CT in HU (NIfTI descrip 'Abdomen CT"), std::string::npos) << c.rule;
  engine::VolumeHints u;
  io::read_text_hints("NRRD", {{"content", "liver"}, {"units", "Hounsfield"}}, u);
  EXPECT_EQ(u.modality, "");
  EXPECT_EQ(u.units, "HU");
  EXPECT_TRUE(engine::choose_isovalue(volume_of(x), u).hounsfield);
  // An industrial CT in 8 bits says "CT" too: its values (no air below -500) overrule it.
  EXPECT_FALSE(engine::choose_isovalue(volume_of({0, 10, 120, 255}), h).hounsfield);
  // Words, not letters inside words: "ACT", "strict", "HUB" say nothing.
  engine::VolumeHints none;
  io::read_text_hints("NIfTI", {{"descrip", "ACT strict HUB protocol"}}, none);
  EXPECT_EQ(none.modality, "");
  EXPECT_EQ(none.units, "");
}

TEST(ChooseIsovalue, OtherDataAtTheUpperThreeClassOtsuThreshold) {
  std::vector<float> x;
  add_uniform(x, 0, 50, 50000);
  add_uniform(x, 500, 700, 40000);
  add_uniform(x, 1200, 1600, 10000);
  const Volume v = volume_of(x);
  const auto c = engine::choose_isovalue(v, {});
  EXPECT_FALSE(c.hounsfield);
  EXPECT_TRUE(c.presets.empty());
  EXPECT_EQ(c.iso.tau, engine::otsu_thresholds(engine::histogram(v, 256), 3)[1]);
  EXPECT_NE(c.rule.find("three-class Otsu"), std::string::npos) << c.rule;
}

TEST(ChooseIsovalue, DegenerateVolumesGiveAFiniteValueAndSaySo) {
  const auto flat = engine::choose_isovalue(volume_of({7, 7, 7}), {});
  EXPECT_EQ(flat.iso.tau, 7);
  EXPECT_NE(flat.rule.find("constant"), std::string::npos) << flat.rule;
  const auto none = engine::choose_isovalue(volume_of({NAN, NAN}), {});
  EXPECT_TRUE(std::isfinite(none.iso.tau));
  EXPECT_NE(none.rule.find("no finite voxels"), std::string::npos) << none.rule;
}

TEST(Scan, ShippedHeadIsNotHuAndOpensAboveTheTwoClassSkinThreshold) {
  const io::Scan s = io::load_scan(kHead);
  const auto c = io::choose_isovalue(s);
  EXPECT_FALSE(c.hounsfield);
  EXPECT_NE(c.rule.find("three-class Otsu"), std::string::npos) << c.rule;
  // The two-class split lands on skin; bone is denser.
  const double skin = engine::otsu_thresholds(engine::histogram(s.volume, 256), 2)[0];
  EXPECT_GT(c.iso.tau, skin + 300) << c.rule;
}

TEST(Scan, ChestIsHuByItsMinimumAndItsDicomSeriesByTheModality) {
  const auto mhd = io::choose_isovalue(io::load_scan(kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd"));
  EXPECT_TRUE(mhd.hounsfield);
  EXPECT_EQ(mhd.iso.tau, 300);
  EXPECT_NE(mhd.rule.find("minimum -1024"), std::string::npos) << mhd.rule;
  const io::Scan dcm = io::load_scan(kData + "/ct-chest-lungdx-a0001/dicom-5mm");
  EXPECT_EQ(dcm.hints.modality, "CT");
  EXPECT_NE(io::choose_isovalue(dcm).rule.find("modality CT"), std::string::npos);
}

/// A NIfTI-1 file (.nii) of int16 voxels with `descrip` in its header, written byte by byte
/// from the format's definition (nifti1.h), not by the code under test.
void write_nifti(const fs::path& p, const std::string& descrip, int nx, int ny, int nz, const std::vector<std::int16_t>& v) {
  std::vector<char> h(352, 0);
  const auto put = [&](std::size_t off, const void* src, std::size_t n) { std::memcpy(h.data() + off, src, n); };
  const std::int32_t sizeof_hdr = 348;
  put(0, &sizeof_hdr, 4);
  const std::int16_t dim[8] = {3, std::int16_t(nx), std::int16_t(ny), std::int16_t(nz), 1, 1, 1, 1};
  put(40, dim, 16);
  const std::int16_t datatype = 4, bitpix = 16;  // DT_INT16
  put(70, &datatype, 2);
  put(72, &bitpix, 2);
  const float pixdim[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  put(76, pixdim, 32);
  const float vox_offset = 352, scl_slope = 1;
  put(108, &vox_offset, 4);
  put(112, &scl_slope, 4);
  put(148, descrip.data(), std::min<std::size_t>(descrip.size(), 79));
  put(344, "n+1", 4);
  std::ofstream out(p, std::ios::binary);
  out.write(h.data(), std::streamsize(h.size()));
  out.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 2));
}

TEST(Scan, NiftiDescriptionAndNrrdContentAreRead) {
  test::TempDir dir;
  // 8 x 8 x 8, values -600 .. 1100: HU only by the header's word.
  std::vector<std::int16_t> v(512);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = std::int16_t(-600 + int(i) * 1700 / 512);
  write_nifti(dir.path / "ct.nii", "CT abdomen", 8, 8, 8, v);
  const io::Scan nii = io::load_scan((dir.path / "ct.nii").string());
  EXPECT_EQ(nii.hints.modality, "CT");
  const auto c = io::choose_isovalue(nii);
  EXPECT_TRUE(c.hounsfield);
  EXPECT_NE(c.rule.find("NIfTI descrip 'CT abdomen'"), std::string::npos) << c.rule;
  write_nifti(dir.path / "mr.nii", "T1 MPRAGE", 8, 8, 8, v);
  EXPECT_FALSE(io::choose_isovalue(io::load_scan((dir.path / "mr.nii").string())).hounsfield);
  // NRRD: its content and key/value pairs.
  std::ofstream(dir.path / "ct.nrrd") << "NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2 2\nspacings: 1 1 1\n"
                                          "encoding: ascii\ncontent: liver\nmodality:=CT\n\n-600 -100 0 40 60 300 900 1100\n";
  const io::Scan nrrd = io::load_scan((dir.path / "ct.nrrd").string());
  EXPECT_EQ(nrrd.hints.modality, "CT");
  EXPECT_EQ(nrrd.hints.modality_from, "NRRD modality 'CT'");
  EXPECT_TRUE(io::choose_isovalue(nrrd).hounsfield);
  // The shipped engine block (NIfTI, industrial CT in 8 bits) says no modality.
  const io::Scan engine_ct = io::load_scan(kData + "/ct-engine/engine.nii.gz");
  EXPECT_EQ(engine_ct.hints.modality, "");
  EXPECT_FALSE(io::choose_isovalue(engine_ct).hounsfield);
}

TEST(Scan, MetaImageModalityIsRead) {
  test::TempDir dir;
  const fs::path mhd = dir.path / "ct.mhd";
  std::ofstream(mhd) << "ObjectType = Image\nNDims = 3\nModality = MET_MOD_CT\nDimSize = 64 64 93\n"
                        "ElementType = MET_SHORT\nElementSpacing = 3.2 3.2 1.5\nElementDataFile = "
                     << fs::path(kHead).replace_extension(".raw").string() << "\n";
  EXPECT_EQ(io::metaimage_modality(mhd.string()), "CT");
  EXPECT_EQ(io::metaimage_modality(kHead), "");
  const auto c = io::choose_isovalue(io::load_scan(mhd.string()));
  EXPECT_TRUE(c.hounsfield);
  EXPECT_NE(c.rule.find("modality CT"), std::string::npos) << c.rule;
}

TEST(Scan, VdbOpensAtTheIsovalueItStores) {
  test::TempDir dir;
  const std::string vdb = (dir.path / "head.vdb").string();
  io::SaveVdbOptions so;
  so.iso = core::Isosurface{987.5, core::InsideIs::kAbove};
  io::save_vdb(io::load_volume(kHead), vdb, so);
  const auto c = io::choose_isovalue(io::load_scan(vdb));
  EXPECT_EQ(c.iso.tau, 987.5);
  EXPECT_NE(c.rule.find(".vdb metadata"), std::string::npos) << c.rule;
  // Without the metadata: the histogram's rule, as for the file it came from.
  const std::string bare = (dir.path / "bare.vdb").string();
  io::save_vdb(io::load_volume(kHead), bare);
  const auto b = io::choose_isovalue(io::load_scan(bare));
  EXPECT_EQ(b.iso.tau, io::choose_isovalue(io::load_scan(kHead)).iso.tau);
}

}  // namespace
}  // namespace isotouch
