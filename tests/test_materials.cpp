// The materials module (materials/): label maps (NRRD, NIfTI), 3D Slicer's .seg.nrrd and
// transfer functions read onto the scan's grid, and the scene's "materials" section. Every
// label map is written here byte by byte (its header by hand), so what a voxel must read
// comes from the test, not from the readers under test.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "isotouch/engine/volume.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/materials/label_export.h"
#include "isotouch/materials/label_volume.h"
#include "isotouch/materials/seg_nrrd.h"
#include "isotouch/tests/temp_dir.h"

using namespace isotouch;
using materials::Material;
using materials::MaterialError;
using materials::MaterialsSpec;

namespace {

struct Dims {
  int x, y, z;
  std::size_t count() const { return std::size_t(x) * std::size_t(y) * std::size_t(z); }
};

/// A NRRD (LPS, raw, little endian) of `type` ("uint8" or "float") voxels, spacing and origin
/// in mm, with extra "key:=value" lines.
void write_nrrd(const std::string& path, Dims d, const std::string& type, const void* data, std::size_t bytes,
                double spacing_mm, std::array<double, 3> origin_mm, const std::vector<std::string>& keys = {}) {
  std::ofstream f(path, std::ios::binary);
  f << "NRRD0004\ntype: " << type << "\ndimension: 3\nspace: left-posterior-superior\nsizes: " << d.x << " " << d.y
    << " " << d.z << "\nspace directions: (" << spacing_mm << ",0,0) (0," << spacing_mm << ",0) (0,0," << spacing_mm
    << ")\nkinds: domain domain domain\nendian: little\nencoding: raw\nspace origin: (" << origin_mm[0] << ","
    << origin_mm[1] << "," << origin_mm[2] << ")\n";
  for (const std::string& k : keys) f << k << "\n";
  f << "\n";
  f.write(static_cast<const char*>(data), std::streamsize(bytes));
}

/// A NIfTI-1 (.nii) of uint8 voxels, 1 mm, qform identity at the origin: ITK reads it in LPS
/// with direction diag(-1, -1, 1) and origin (0, 0, 0).
void write_nifti_u8(const std::string& path, Dims d, const std::vector<std::uint8_t>& v) {
  std::vector<char> h(352, 0);
  auto put = [&](std::size_t at, auto x) { std::memcpy(h.data() + at, &x, sizeof x); };
  put(0, std::int32_t(348));
  const std::int16_t dim[8] = {3, std::int16_t(d.x), std::int16_t(d.y), std::int16_t(d.z), 1, 1, 1, 1};
  std::memcpy(h.data() + 40, dim, sizeof dim);
  put(70, std::int16_t(2));  // DT_UNSIGNED_CHAR
  put(72, std::int16_t(8));  // bitpix
  const float pixdim[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  std::memcpy(h.data() + 76, pixdim, sizeof pixdim);
  put(108, float(352));       // vox_offset
  put(123, char(2));          // xyzt_units: mm
  put(252, std::int16_t(1));  // qform_code: scanner
  std::memcpy(h.data() + 344, "n+1\0", 4);
  std::ofstream f(path, std::ios::binary);
  f.write(h.data(), std::streamsize(h.size()));
  f.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size()));
}

/// A scan of `d` voxels of 1 mm at the origin, direction `dir`, voxel value = its x index.
engine::Volume scan(Dims d, std::array<double, 9> dir = {1, 0, 0, 0, 1, 0, 0, 0, 1}) {
  engine::Volume v;
  v.grid.dims = {d.x, d.y, d.z};
  v.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  v.path = "synthetic:test-scan";
  v.direction = dir;
  v.direction_is_identity = dir == std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1};
  v.voxels.resize(d.count());
  for (std::size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i % std::size_t(d.x));
  v.update_stats();
  return v;
}

/// Label values by x: `per_x[x]` at every voxel of column x.
std::vector<std::uint8_t> by_x(Dims d, const std::vector<std::uint8_t>& per_x) {
  std::vector<std::uint8_t> v(d.count());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = per_x[i % std::size_t(d.x)];
  return v;
}

Material mat(const std::string& name, int label) {
  Material m;
  m.name = name;
  m.label = label;
  return m;
}

/// Every voxel's id is `want[x]`.
void expect_ids_by_x(const materials::LabelVolume& lv, Dims d, const std::vector<int>& want) {
  ASSERT_EQ(lv.ids.size(), d.count());
  for (int z = 0; z < d.z; ++z)
    for (int y = 0; y < d.y; ++y)
      for (int x = 0; x < d.x; ++x) ASSERT_EQ(int(lv.at(x, y, z)), want[std::size_t(x)]) << "voxel " << x << "," << y << "," << z;
}

/// The message of the MaterialError `f` throws ("" if it throws none).
std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const MaterialError& e) {
    return e.what();
  }
  return "";
}

const Dims kD{6, 3, 2};

}  // namespace

TEST(Materials, NrrdLabelMapGivesEachScanVoxelTheMaterialOfItsLabel) {
  test::TempDir dir;
  const std::string p = (dir.path / "labels.nrrd").string();
  const auto v = by_x(kD, {0, 7, 7, 3, 3, 0});
  write_nrrd(p, kD, "uint8", v.data(), v.size(), 1.0, {0, 0, 0});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("bone", 7), mat("soft", 3)};  // ids 1, 2: the list's order, not the label values'
  const materials::LabelVolume lv = materials::load_label_volume(spec, scan(kD));
  expect_ids_by_x(lv, kD, {0, 1, 1, 2, 2, 0});
  EXPECT_EQ(lv.voxels, (std::vector<std::size_t>{12, 12, 12}));
  EXPECT_TRUE(lv.notes.empty()) << lv.notes[0];
}

TEST(Materials, NiftiLabelMapOnTheScanGridReadsTheSame) {
  test::TempDir dir;
  const std::string p = (dir.path / "labels.nii").string();
  write_nifti_u8(p, kD, by_x(kD, {1, 1, 2, 2, 0, 5}));
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("a", 1), mat("b", 2), mat("c", 5)};
  const auto lv = materials::load_label_volume(spec, scan(kD, {-1, 0, 0, 0, -1, 0, 0, 0, 1}));
  expect_ids_by_x(lv, kD, {1, 1, 2, 2, 0, 3});
  EXPECT_TRUE(lv.notes.empty()) << lv.notes[0];
}

TEST(Materials, SegNrrdGivesNamedMaterialsTheirSegmentsLabelValuesAndColours) {
  test::TempDir dir;
  const std::string p = (dir.path / "tooth.seg.nrrd").string();
  const auto v = by_x(kD, {0, 4, 4, 9, 9, 9});
  write_nrrd(p, kD, "uint8", v.data(), v.size(), 1.0, {0, 0, 0},
             {"Segment0_Name:=dentin", "Segment0_LabelValue:=9", "Segment0_Layer:=0", "Segment0_Color:=0.9 0.8 0.5",
              "Segment1_Name:=enamel", "Segment1_LabelValue:=4", "Segment1_Layer:=0", "Segment1_Color:=1 1 0.25"});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("enamel", -1), mat("dentin", -1)};
  spec.list[1].color = {0, 0, 1};
  spec.list[1].has_color = true;  // the scene's colour wins over the segment's
  const auto lv = materials::load_label_volume(spec, scan(kD));
  expect_ids_by_x(lv, kD, {0, 1, 1, 2, 2, 2});
  EXPECT_EQ(lv.materials[0].label, 4);
  EXPECT_EQ(lv.materials[1].label, 9);
  EXPECT_EQ(lv.materials[0].color, (std::array<double, 3>{1, 1, 0.25}));
  EXPECT_EQ(lv.materials[1].color, (std::array<double, 3>{0, 0, 1}));
}

TEST(Materials, TransferFunctionTakesTheFirstRangeHoldingTheValue) {
  MaterialsSpec spec;
  spec.list = {mat("low", -1), mat("high", -1)};
  spec.list[0].range_lo = 1, spec.list[0].range_hi = 3;  // values 1, 2
  spec.list[1].range_lo = 4, spec.list[1].range_hi = 99;  // values 4, 5 (3 is no one's)
  const auto lv = materials::load_label_volume(spec, scan(kD));
  expect_ids_by_x(lv, kD, {0, 1, 1, 0, 2, 2});
  EXPECT_EQ(lv.source, "transfer function");
}

TEST(Materials, LabelMapOnAnotherGridIsResampledNearestNeighbourAndTheLogSaysSo) {
  // Label voxels of 2 mm from -0.5 mm: scan voxel x (1 mm from 0) lies at label index
  // x / 2 + 0.25, nearest round(x / 2 + 0.25); scan x = 7 lies at 3.75 -> 4, beyond the map: 0.
  test::TempDir dir;
  const std::string p = (dir.path / "coarse.nrrd").string();
  const Dims ld{4, 2, 2};
  const Dims sd{8, 3, 2};
  const auto v = by_x(ld, {1, 2, 3, 4});
  write_nrrd(p, ld, "uint8", v.data(), v.size(), 2.0, {-0.5, -0.5, -0.5});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("a", 1), mat("b", 2), mat("c", 3), mat("d", 4)};
  const auto lv = materials::load_label_volume(spec, scan(sd));
  expect_ids_by_x(lv, sd, {1, 2, 2, 3, 3, 4, 4, 0});
  ASSERT_EQ(lv.notes.size(), 1u);
  EXPECT_NE(lv.notes[0].find("resampled onto the scan's grid, nearest neighbour"), std::string::npos) << lv.notes[0];
  EXPECT_NE(lv.notes[0].find(p), std::string::npos) << lv.notes[0];
}

TEST(Materials, UnknownLabelValueIsAnErrorNamingTheFileAndTheValue) {
  test::TempDir dir;
  const std::string p = (dir.path / "labels.nrrd").string();
  const auto v = by_x(kD, {0, 1, 1, 9, 1, 1});
  write_nrrd(p, kD, "uint8", v.data(), v.size(), 1.0, {0, 0, 0});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("a", 1)};
  const std::string e = error_of([&] { materials::load_label_volume(spec, scan(kD)); });
  EXPECT_NE(e.find(p + ": label value 9 (first at scan voxel (3, 0, 0)) is no material's"), std::string::npos) << e;
}

TEST(Materials, LabelMapCoveringNoScanVoxelIsAGridMismatch) {
  test::TempDir dir;
  const std::string p = (dir.path / "far.nrrd").string();
  const auto v = by_x(kD, {1, 1, 1, 1, 1, 1});
  write_nrrd(p, kD, "uint8", v.data(), v.size(), 1.0, {500, 0, 0});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("a", 1)};
  const std::string e = error_of([&] { materials::load_label_volume(spec, scan(kD)); });
  EXPECT_NE(e.find(p + ": grid mismatch: the label map (6x3x2 voxels of 1 x 1 x 1 mm at (500, 0, 0) mm) covers no voxel"),
            std::string::npos)
      << e;
}

TEST(Materials, LabelThatIsNotAWholeNumberIsAWrongTypeError) {
  test::TempDir dir;
  const std::string p = (dir.path / "float.nrrd").string();
  std::vector<float> v(kD.count(), 1.0f);
  v[2] = 1.5f;  // voxel (2, 0, 0)
  write_nrrd(p, kD, "float", v.data(), v.size() * sizeof(float), 1.0, {0, 0, 0});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("a", 1)};
  const std::string e = error_of([&] { materials::load_label_volume(spec, scan(kD)); });
  EXPECT_NE(e.find(p + ": voxel (2, 0, 0) holds 1.5 (voxel type float): a label map holds whole label values"),
            std::string::npos)
      << e;
}

TEST(Materials, MaterialWithNoSegmentOfItsNameIsAnError) {
  test::TempDir dir;
  const std::string p = (dir.path / "one.seg.nrrd").string();
  const auto v = by_x(kD, {0, 1, 1, 1, 1, 0});
  write_nrrd(p, kD, "uint8", v.data(), v.size(), 1.0, {0, 0, 0},
             {"Segment0_Name:=pulp", "Segment0_LabelValue:=1", "Segment0_Layer:=0", "Segment0_Color:=1 0 0"});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("enamel", -1)};
  const std::string e = error_of([&] { materials::load_label_volume(spec, scan(kD)); });
  EXPECT_NE(e.find(p + ": materials.list[0] \"enamel\": no segment of that name (segments: pulp = 1)"), std::string::npos) << e;
}

TEST(Materials, MissingSegNrrdIsNamedByTheVolumeReaderNotTakenForAHeaderWithoutSegments) {
  test::TempDir dir;
  MaterialsSpec spec;
  spec.labels_path = (dir.path / "gone.seg.nrrd").string();
  spec.list = {mat("enamel", -1)};
  try {
    materials::load_label_volume(spec, scan(kD));
    ADD_FAILURE() << "no error";
  } catch (const engine::VolumeError& e) {
    EXPECT_NE(std::string(e.what()).find(spec.labels_path), std::string::npos) << e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not the volume reader's error: " << e.what();
  }
}

// The .seg.nrrd header's segments, key by key.
namespace {
using Keys = std::vector<std::pair<std::string, std::string>>;
Keys two_segments() {
  return {{"Segment0_Name", "enamel"}, {"Segment0_LabelValue", "1"}, {"Segment0_Layer", "0"}, {"Segment0_Color", "1 1 1"},
          {"Segment1_Name", "pulp"},   {"Segment1_LabelValue", "3"}, {"Segment1_Layer", "0"}, {"Segment1_Color", "1 0 0"},
          {"content", "not a segment key"}};
}
std::string seg_error(const Keys& k) {
  return error_of([&] { materials::parse_seg_nrrd_segments(k, "t.seg.nrrd"); });
}
Keys without(Keys k, const std::string& key) {
  std::erase_if(k, [&](const auto& kv) { return kv.first == key; });
  return k;
}
Keys with(Keys k, const std::string& key, const std::string& value) {
  for (auto& kv : k)
    if (kv.first == key) kv.second = value;
  return k;
}
}  // namespace

TEST(SegNrrd, ReadsEverySegmentsFourKeys) {
  const auto s = materials::parse_seg_nrrd_segments(two_segments(), "t.seg.nrrd");
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s[1].name, "pulp");
  EXPECT_EQ(s[1].label_value, 3);
  EXPECT_EQ(s[1].color, (std::array<double, 3>{1, 0, 0}));
}

TEST(SegNrrd, EachMissingKeyIsNamed) {
  for (const char* k : {"Segment1_Name", "Segment1_LabelValue", "Segment1_Layer", "Segment1_Color"})
    EXPECT_NE(seg_error(without(two_segments(), k)).find(std::string("t.seg.nrrd: header key '") + k + "': missing"),
              std::string::npos)
        << k;
  EXPECT_NE(seg_error({{"content", "x"}}).find("header key 'Segment0_Name': missing: no SegmentN_ keys"), std::string::npos);
  // A gap: Segment0 absent while Segment1 is there.
  Keys gap = two_segments();
  std::erase_if(gap, [](const auto& kv) { return kv.first.rfind("Segment0_", 0) == 0; });
  EXPECT_NE(seg_error(gap).find("'Segment0_Name': missing"), std::string::npos);
}

TEST(SegNrrd, BadValuesAreNamedWithTheirValue) {
  EXPECT_NE(seg_error(with(two_segments(), "Segment1_LabelValue", "2.5")).find("'Segment1_LabelValue': must be an integer in [1, 65535], got \"2.5\""),
            std::string::npos);
  EXPECT_NE(seg_error(with(two_segments(), "Segment1_LabelValue", "1")).find("'Segment1_LabelValue': 1 is an earlier segment's"),
            std::string::npos);
  EXPECT_NE(seg_error(with(two_segments(), "Segment1_Layer", "1")).find("'Segment1_Layer': 1: overlapping segments"),
            std::string::npos);
  EXPECT_NE(seg_error(with(two_segments(), "Segment1_Color", "1 0")).find("'Segment1_Color': must be \"R G B\""),
            std::string::npos);
  EXPECT_NE(seg_error(with(two_segments(), "Segment1_Color", "1 0 2")).find("'Segment1_Color'"), std::string::npos);
  EXPECT_NE(seg_error(with(two_segments(), "Segment1_Name", "enamel")).find("'Segment1_Name': \"enamel\" is empty or names an earlier"),
            std::string::npos);
}

// The scene's "materials" section.
namespace {
std::string scene_with(const std::string& materials_json) {
  return R"({"volume": {"synthetic": "sphere"}, "isovalue": 0, "inside": "below", "materials": )" + materials_json + "}";
}
std::string scene_error(const std::string& materials_json) {
  try {
    io::parse_scene(scene_with(materials_json), "/s/t.json");
  } catch (const io::SceneError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(MaterialsScene, ReadsEveryFieldOfALabelMapsMaterials) {
  const io::Scene s = io::parse_scene(scene_with(R"({"labels": "l.nrrd", "list": [
      {"name": "bone", "label": 2, "stiffness_n_per_m": 1500, "mu_s": 0.4, "mu_d": 0.3, "rate": 50,
       "density_scale": 900, "color": [1, 0.9, 0.8], "critical": true, "margin_mm": 1.5}]})"),
                                      "/s/t.json");
  ASSERT_TRUE(s.materials.present);
  EXPECT_EQ(s.materials.labels_path, "/s/l.nrrd");
  ASSERT_EQ(s.materials.list.size(), 1u);
  const Material& m = s.materials.list[0];
  EXPECT_EQ(m.name, "bone");
  EXPECT_EQ(m.label, 2);
  EXPECT_EQ(m.stiffness_n_per_m, 1500);
  EXPECT_EQ(m.mu_s, 0.4);
  EXPECT_EQ(m.mu_d, 0.3);
  EXPECT_EQ(m.rate, 50);
  EXPECT_EQ(m.density_scale, 900);
  EXPECT_EQ(m.color, (std::array<double, 3>{1, 0.9, 0.8}));
  EXPECT_TRUE(m.critical);
  EXPECT_EQ(m.margin_mm, 1.5);
}

TEST(MaterialsScene, BadFieldsAreNamed) {
  EXPECT_NE(scene_error(R"({"labels": "l.nrrd", "list": [{"name": "a"}]})").find("field 'materials.list[0].label': is required with a label map"),
            std::string::npos);
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5]}, {"name": "b", "range": [4, 9]}]})")
                .find("field 'materials.list[1].range': [4,9] overlaps \"a\"'s"),
            std::string::npos);
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5], "mu_s": 0.1, "mu_d": 0.2}]})").find("field 'materials.list[0].mu_d': must be at most mu_s"),
            std::string::npos);
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5], "stiffness_n_per_m": -1}]})")
                .find("field 'materials.list[0].stiffness_n_per_m': must be in (0, 1e6], got -1"),
            std::string::npos);
  EXPECT_NE(scene_error(R"({"labels": "l.nrrd", "list": [{"name": "a", "label": 1}, {"name": "b", "label": 1}]})")
                .find("field 'materials.list[1].label': 1 is \"a\"'s label too"),
            std::string::npos);
  EXPECT_NE(scene_error(R"({"list": []})").find("field 'materials.list': must be an array of 1 to 255"), std::string::npos);
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5], "colour": [1, 1, 1]}]})").find("field 'materials.list[0].colour': unknown field"),
            std::string::npos);
}

// The shipped labelled scenes (tools/make_tooth_labels.py): the NIfTI label map, the
// .seg.nrrd and the transfer function are three readers of the same thresholds, so they must
// agree voxel for voxel, on the scan's own grid, with every material present.
TEST(MaterialsScene, ShippedToothScenesAgreeVoxelForVoxelInEveryForm) {
  const std::string scenes = std::string(ISOTOUCH_TEST_DATA) + "/../scenes/";
  std::vector<materials::LabelVolume> forms;
  for (const char* name : {"tooth-labels", "tooth-seg", "tooth-transfer"}) {
    const io::Scene s = io::load_scene(scenes + name + ".json");
    const engine::Volume tooth = io::load_volume(s.volume_path);
    forms.push_back(materials::load_label_volume(s.materials, tooth));
    EXPECT_TRUE(forms.back().notes.empty()) << name << ": " << forms.back().notes[0];
    for (std::size_t id = 1; id < forms.back().voxels.size(); ++id) EXPECT_GT(forms.back().voxels[id], 0u) << name << " id " << id;
  }
  EXPECT_EQ(forms[0].source.rfind("label map ", 0), 0u) << forms[0].source;
  EXPECT_EQ(forms[1].source.rfind("3D Slicer segmentation ", 0), 0u) << forms[1].source;
  EXPECT_TRUE(forms[0].ids == forms[1].ids) << "the NIfTI label map and the .seg.nrrd differ";
  EXPECT_TRUE(forms[0].ids == forms[2].ids) << "the label map and the transfer function differ";
  for (std::size_t m = 0; m < forms[0].materials.size(); ++m)
    EXPECT_EQ(forms[1].materials[m].color, forms[0].materials[m].color) << forms[0].materials[m].name;
}

TEST(Materials, SegNrrdMaterialWhoseSegmentHasAnotherMaterialsLabelIsAnError) {
  test::TempDir dir;
  const std::string p = (dir.path / "two.seg.nrrd").string();
  const auto v = by_x(kD, {0, 4, 4, 9, 9, 9});
  write_nrrd(p, kD, "uint8", v.data(), v.size(), 1.0, {0, 0, 0},
             {"Segment0_Name:=dentin", "Segment0_LabelValue:=9", "Segment0_Layer:=0", "Segment0_Color:=0.9 0.8 0.5",
              "Segment1_Name:=enamel", "Segment1_LabelValue:=4", "Segment1_Layer:=0", "Segment1_Color:=1 1 0.25"});
  MaterialsSpec spec;
  spec.labels_path = p;
  spec.list = {mat("enamel", -1), mat("bone", 4)};  // "enamel" is filled in as 4, "bone" writes 4
  const std::string e = error_of([&] { materials::load_label_volume(spec, scan(kD)); });
  EXPECT_NE(e.find(p + ": materials.list[1] \"bone\" and materials.list[0] \"enamel\" both have label value 4"),
            std::string::npos)
      << e;
}

TEST(SegNrrd, SegmentKeyWhoseIndexDoesNotParseCleanlyIsNamed) {
  for (const char* k : {"Segment99999999999999999999_Name", "Segment-1_Name", "Segment01_Name", "Segment+1_Name"}) {
    Keys keys = two_segments();
    keys.push_back({k, "x"});
    EXPECT_NE(seg_error(keys).find(std::string("t.seg.nrrd: header key '") + k + "'"), std::string::npos) << k;
  }
}

TEST(SegNrrd, TwoKeysForOneSegmentFieldAreNamed) {
  Keys keys = {{"Segment0_Name", "enamel"}, {"Segment0_LabelValue", "1"}, {"Segment0_Layer", "0"}, {"Segment0_Color", "1 1 1"},
               {"Segment0_Name", "dentin"}};
  EXPECT_NE(seg_error(keys).find("t.seg.nrrd: header key 'Segment0_Name': given twice"), std::string::npos) << seg_error(keys);
}

TEST(MaterialsScene, MarginIsForCriticalMaterialsOnly) {
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5], "margin_mm": 1}]})")
                .find("field 'materials.list[0].margin_mm': only a critical material has a margin, got 1"),
            std::string::npos)
      << scene_error(R"({"list": [{"name": "a", "range": [0, 5], "margin_mm": 1}]})");
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5], "critical": true}]})")
                .find("field 'materials.list[0].margin_mm': is required above 0 for a critical material, got 0"),
            std::string::npos)
      << scene_error(R"({"list": [{"name": "a", "range": [0, 5], "critical": true}]})");
}

TEST(SegNrrd, SegmentIndex255IsReadAnd256Refused) {
  Keys keys = two_segments();
  for (int n = 2; n <= 255; ++n)
    for (const auto& [f, v] : Keys{{"Name", "s" + std::to_string(n)}, {"LabelValue", std::to_string(n + 2)}, {"Layer", "0"}, {"Color", "0 0 0"}})
      keys.push_back({"Segment" + std::to_string(n) + "_" + f, v});
  EXPECT_EQ(materials::parse_seg_nrrd_segments(keys, "t.seg.nrrd").size(), 256u);
  keys.push_back({"Segment256_Name", "s256"});
  EXPECT_NE(seg_error(keys).find("header key 'Segment256_Name': segment index 256 above 255"), std::string::npos) << seg_error(keys);
}

TEST(SegNrrd, LabelValueBoundaries) {
  for (const char* bad : {"0", "65536", "-1"})
    EXPECT_NE(seg_error(with(two_segments(), "Segment1_LabelValue", bad))
                  .find(std::string("'Segment1_LabelValue': must be an integer in [1, 65535], got \"") + bad + "\""),
              std::string::npos)
        << bad;
  EXPECT_EQ(materials::parse_seg_nrrd_segments(with(two_segments(), "Segment1_LabelValue", "65535"), "t.seg.nrrd")[1].label_value, 65535);
  for (const char* bad : {"1.0001 0 0", "-0.01 0 0"})
    EXPECT_NE(seg_error(with(two_segments(), "Segment1_Color", bad)).find("'Segment1_Color': must be \"R G B\""), std::string::npos) << bad;
}

TEST(MaterialsScene, BoundaryValues) {
  EXPECT_NE(scene_error(R"({"list": [{"name": "a", "range": [0, 5], "stiffness_n_per_m": 0}]})")
                .find("field 'materials.list[0].stiffness_n_per_m': must be in (0, 1e6], got 0"),
            std::string::npos);
  for (const char* c : {"[1.0001, 0, 0]", "[-0.01, 0, 0]"})
    EXPECT_NE(scene_error(std::string(R"({"list": [{"name": "a", "range": [0, 5], "color": )") + c + "}]}")
                  .find("field 'materials.list[0].color': must be [r, g, b], each in [0, 1]"),
              std::string::npos)
        << c;
}

// The edited label map for 3D Slicer (materials/label_export.h), round trip through this
// project's own readers: the shipped tooth's labels, "drilled" here by the test (a ball of
// voxels set to 0, the empty value below the isovalue), written as .seg.nrrd and read back by
// load_label_volume by segment name alone. Truth: the label volume as loaded and the ball's
// geometry, not the writer.
TEST(LabelExport, DrilledToothRoundTripsThroughTheSegNrrdReader) {
  const std::string scenes = std::string(ISOTOUCH_TEST_DATA) + "/../scenes/";
  const io::Scene s = io::load_scene(scenes + "tooth-labels.json");
  const engine::Volume tooth = io::load_volume(s.volume_path);
  const materials::LabelVolume lv = materials::load_label_volume(s.materials, tooth);
  const core::Isosurface iso{s.hri.tau, s.hri.inside};
  // The ball: centred on the first inside voxel met going +y at x = 51, z = 92 (the drill
  // scene's path), radius 6 voxels.
  const auto& d = tooth.grid.dims;
  int cy = 0;
  while (cy < d[1] && !iso.contains(tooth.voxels[tooth.grid.index(51, cy, 92)])) ++cy;
  ASSERT_LT(cy, d[1]);
  std::vector<float> after = tooth.voxels;
  std::vector<std::uint8_t> want = lv.ids;
  std::vector<std::size_t> removed_per_id(lv.materials.size() + 1, 0);
  std::size_t kept_outside = 0;
  for (int z = 0; z < d[2]; ++z)
    for (int y = 0; y < d[1]; ++y)
      for (int x = 0; x < d[0]; ++x) {
        const int dx = x - 51, dy = y - cy, dz = z - 92;
        if (dx * dx + dy * dy + dz * dz > 36) continue;
        const std::size_t i = tooth.grid.index(x, y, z);
        after[i] = 0.0f;
        if (double(tooth.voxels[i]) > s.hri.tau) {  // inside before (the scene's inside is above): removed
          ++removed_per_id[lv.ids[i]];
          want[i] = 0;
        } else if (lv.ids[i] != 0) {
          ++kept_outside;  // a labelled voxel outside the surface from the start keeps its label
        }
      }
  ASSERT_GT(removed_per_id[1] + removed_per_id[2], 0u) << "the ball removed no enamel or dentin";
  const std::vector<std::uint8_t> edited = materials::edited_ids(lv.ids, tooth.voxels, after, iso);
  test::TempDir dir;
  const std::string out = (dir.path / "tooth-drilled.seg.nrrd").string();
  materials::write_seg_nrrd(out, edited, lv.materials, tooth);
  // Read back by segment name alone: label values and colours from the file's segments.
  MaterialsSpec back;
  back.present = true;
  back.labels_path = out;
  for (const Material& m : s.materials.list) back.list.push_back(mat(m.name, -1));
  const materials::LabelVolume rt = materials::load_label_volume(back, tooth);
  EXPECT_TRUE(rt.notes.empty()) << rt.notes[0];  // on the scan's grid: not resampled
  ASSERT_EQ(rt.ids.size(), want.size());
  std::size_t zeroed = 0, unchanged = 0;
  for (std::size_t i = 0; i < want.size(); ++i) {
    ASSERT_EQ(int(rt.ids[i]), int(want[i])) << "voxel " << i << " was " << int(lv.ids[i]);
    (want[i] != lv.ids[i] ? zeroed : unchanged) += 1;
  }
  EXPECT_EQ(zeroed, removed_per_id[1] + removed_per_id[2] + removed_per_id[3]);
  EXPECT_EQ(unchanged + zeroed, want.size());
  for (std::size_t m = 0; m < lv.materials.size(); ++m) {
    EXPECT_EQ(rt.materials[m].label, lv.materials[m].label) << lv.materials[m].name;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rt.materials[m].color[c], lv.materials[m].color[c], 1e-12) << lv.materials[m].name;
  }
  std::cout << "removed " << zeroed << " voxels (enamel " << removed_per_id[1] << ", dentin " << removed_per_id[2]
            << ", pulp " << removed_per_id[3] << "), " << kept_outside << " labelled voxels in the ball were outside the surface\n";
}

// The writer's geometry and voxel type: a scan with an oblique-free but flipped direction,
// anisotropic spacing and an origin off zero reads back on the same grid (io::load_volume),
// and label values above 255 are written as unsigned short and read back exactly.
TEST(LabelExport, GeometryAndWideLabelValuesRoundTrip) {
  engine::Volume v = scan(kD, {-1, 0, 0, 0, -1, 0, 0, 0, 1});
  v.grid.spacing_m = {0.5e-3, 1.25e-3, 3e-3};
  v.grid.origin_m = {-12.5e-3, 40e-3, 7e-3};
  std::vector<std::uint8_t> ids(kD.count());
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = std::uint8_t(i % 3);
  std::vector<Material> list{mat("low", 7), mat("high", 300)};
  list[1].color = {0.1, 0.2, 0.3};
  test::TempDir dir;
  const std::string out = (dir.path / "wide.seg.nrrd").string();
  materials::write_seg_nrrd(out, ids, list, v);
  const engine::Volume back = io::load_volume(out);
  EXPECT_EQ(back.component_type, "unsigned_short");
  EXPECT_EQ(back.grid.dims, v.grid.dims);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(back.grid.spacing_m[k], v.grid.spacing_m[k], 1e-12);
    EXPECT_NEAR(back.grid.origin_m[k], v.grid.origin_m[k], 1e-12);
  }
  for (std::size_t k = 0; k < 9; ++k) EXPECT_NEAR(back.direction[k], v.direction[k], 1e-12) << k;
  for (std::size_t i = 0; i < ids.size(); ++i)
    ASSERT_EQ(back.voxels[i], ids[i] == 0 ? 0.f : ids[i] == 1 ? 7.f : 300.f) << "voxel " << i;
  MaterialsSpec spec;
  spec.present = true;
  spec.labels_path = out;
  spec.list = {mat("low", -1), mat("high", -1)};
  const materials::LabelVolume rt = materials::load_label_volume(spec, v);
  EXPECT_TRUE(rt.ids == ids);
  EXPECT_EQ(rt.materials[1].color, list[1].color);
}

TEST(LabelExport, BadInputIsNamed) {
  const engine::Volume v = scan(kD);
  test::TempDir dir;
  const std::string out = (dir.path / "bad.seg.nrrd").string();
  std::vector<Material> list{mat("one", 1)};
  EXPECT_NE(error_of([&] { materials::write_seg_nrrd(out, std::vector<std::uint8_t>(3), list, v); }).find("3 labels"),
            std::string::npos);
  std::vector<std::uint8_t> ids(kD.count(), 0);
  ids[5] = 2;
  EXPECT_NE(error_of([&] { materials::write_seg_nrrd(out, ids, list, v); }).find("material id 2"), std::string::npos);
  list[0].name = "two\nlines";
  EXPECT_NE(error_of([&] { materials::write_seg_nrrd(out, std::vector<std::uint8_t>(kD.count()), list, v); })
                .find("materials.list[0].name"),
            std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(out));
}
