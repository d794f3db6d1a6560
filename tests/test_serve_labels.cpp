// A client's label map IMAGE with its LBMETA as serve's materials (issue 66): the LBMETA's
// elements read whole (name, label value, colour), and labels_from_image's checks: the label
// map on the session volume's grid or refused naming the field and both values, every voxel
// value named by the LBMETA or refused naming it, the materials in the LBMETA's order with its
// names, values and colours, a scene material of the same name lending its fields.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include <igtlImageMessage.h>
#include <igtlLabelMetaMessage.h>

#include "isotouch/service/igtl_message.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/service/label_map.h"
#include "isotouch/tests/igtl_test_sender.h"
#include "isotouch/tests/memory_source.h"

namespace isotouch::service {
namespace {

using test::MemorySource;

TEST(ServeLabels, LabelMetaKeepsNamesValuesAndColours) {
  igtl::LabelMetaMessage::Pointer m = igtl::LabelMetaMessage::New();
  m->SetDeviceName("Labels");
  const struct { const char* name; const char* image; int label; std::uint8_t rgba[4]; } sent[] = {
      {"skull", "Seg", 7, {230, 220, 200, 255}}, {"left ventricle", "Organs", 200, {10, 20, 30, 40}}};
  for (const auto& s : sent) {
    igtl::LabelMetaElement::Pointer e = igtl::LabelMetaElement::New();
    e->SetName(s.name);
    e->SetDeviceName(s.image);
    e->SetLabel(igtlUint8(s.label));
    e->SetRGBA(s.rgba[0], s.rgba[1], s.rgba[2], s.rgba[3]);
    m->AddLabelMetaElement(e);
  }
  MemorySource src(test::bytes_of(m));
  const Incoming in = read_message(src, MessageLimits{});
  ASSERT_EQ(in.kind, Incoming::Kind::kLabelMeta) << in.why;
  ASSERT_EQ(in.label_meta.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(in.label_meta[i].name, sent[i].name);
    EXPECT_EQ(in.label_meta[i].image, sent[i].image);
    EXPECT_EQ(in.label_meta[i].label, sent[i].label);
    for (int c = 0; c < 4; ++c) EXPECT_EQ(in.label_meta[i].rgba[std::size_t(c)], sent[i].rgba[c]) << c;
  }
}

/// A 4 x 3 x 2 volume, 1.5 x 2 x 2.5 mm voxels, origin (10, -20, 30) mm, direction identity.
engine::Volume frame() {
  engine::Volume v;
  v.grid.dims = {4, 3, 2};
  v.grid.spacing_m = {1.5e-3, 2e-3, 2.5e-3};
  v.grid.origin_m = {10e-3, -20e-3, 30e-3};
  v.voxels.assign(24, 0.f);
  return v;
}

/// `frame()`'s grid with voxel i = label(i).
engine::Volume labels(const std::function<float(std::size_t)>& label) {
  engine::Volume v = frame();
  for (std::size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = label(i);
  return v;
}

std::vector<LabelMetaEntry> two() {
  return {{"tissue", "Seg", 1, {255, 0, 0, 255}}, {"bone", "Seg", 2, {230, 220, 200, 255}}};
}

std::string refusal(const engine::Volume& l, const std::vector<LabelMetaEntry>& meta) {
  try {
    labels_from_image(l, "Seg", meta, frame(), {});
  } catch (const engine::VolumeError& e) {
    return e.what();
  }
  return "";
}

TEST(ServeLabels, GoodLabelMapGivesTheLbmetaMaterials) {
  // voxel i: 0 (none), 1 (tissue) or 2 (bone) by i % 3
  const materials::LabelVolume lv = labels_from_image(labels([](std::size_t i) { return float(i % 3); }), "Seg", two(),
                                                      frame(), {});
  ASSERT_EQ(lv.materials.size(), 2u);
  EXPECT_EQ(lv.materials[0].name, "tissue");
  EXPECT_EQ(lv.materials[0].label, 1);
  EXPECT_EQ(lv.materials[1].name, "bone");
  EXPECT_EQ(lv.materials[1].label, 2);
  EXPECT_DOUBLE_EQ(lv.materials[1].color[0], 230 / 255.0);
  EXPECT_DOUBLE_EQ(lv.materials[1].color[2], 200 / 255.0);
  EXPECT_FALSE(lv.materials[1].critical);
  ASSERT_EQ(lv.ids.size(), 24u);
  for (std::size_t i = 0; i < 24; ++i) EXPECT_EQ(lv.ids[i], i % 3) << i;
  EXPECT_EQ(lv.voxels, (std::vector<std::size_t>{8, 8, 8}));
  EXPECT_EQ(describe_materials(lv),
            "tissue (label 1, colour #ff0000, 8 voxels), bone (label 2, colour #e6dcc8, 8 voxels)");
  // The ids follow the LBMETA's order, not the values: bone first.
  const std::vector<LabelMetaEntry> swapped = {two()[1], two()[0]};
  const materials::LabelVolume s = labels_from_image(labels([](std::size_t i) { return float(i % 3); }), "Seg",
                                                     swapped, frame(), {});
  EXPECT_EQ(s.materials[0].name, "bone");
  EXPECT_EQ(s.ids[2], 1);  // value 2: bone, id 1
  EXPECT_EQ(s.ids[1], 2);
}

TEST(ServeLabels, SceneMaterialOfTheSameNameLendsItsFields) {
  materials::Material bone;
  bone.name = "bone";
  bone.stiffness_n_per_m = 3000;
  bone.rate = 50;
  bone.density_scale = 900;
  bone.critical = true;
  bone.margin_mm = 1.5;
  bone.color = {0, 0, 1};
  bone.label = 9;
  materials::Material other;
  other.name = "Bone";  // another name (case counts)
  other.critical = true;
  const materials::LabelVolume lv = labels_from_image(labels([](std::size_t i) { return float(i % 3); }), "Seg", two(),
                                                      frame(), {other, bone});
  const materials::Material& b = lv.materials[1];
  EXPECT_TRUE(b.critical);
  EXPECT_DOUBLE_EQ(b.stiffness_n_per_m, 3000);
  EXPECT_DOUBLE_EQ(b.rate, 50);
  EXPECT_DOUBLE_EQ(b.density_scale, 900);
  EXPECT_DOUBLE_EQ(b.margin_mm, 1.5);
  EXPECT_EQ(b.label, 2);                              // the LBMETA's value
  EXPECT_DOUBLE_EQ(b.color[0], 230 / 255.0);          // and colour
  EXPECT_FALSE(lv.materials[0].critical);             // tissue: no scene material
  EXPECT_NE(describe_materials(lv).find("bone (label 2, colour #e6dcc8, 8 voxels, critical)"), std::string::npos);
}

TEST(ServeLabels, ValueTheLbmetaDoesNotNameIsRefused) {
  const std::string why = refusal(labels([](std::size_t i) { return i == 13 ? 5.f : float(i % 3); }), two());
  EXPECT_NE(why.find("igtl:Seg: label value 5 (voxel (1, 0, 1)) is no label of the LBMETA (its label values: 1, 2)"),
            std::string::npos)
      << why;
  // value 0 is no material: a map of zeros and ones needs only tissue
  EXPECT_EQ(refusal(labels([](std::size_t i) { return float(i % 2); }), {two()[0]}), "");
  EXPECT_NE(refusal(labels([](std::size_t i) { return float(i % 3); }), {two()[0]}).find("label value 2"),
            std::string::npos);
  EXPECT_NE(refusal(labels([](std::size_t) { return -1.f; }), two()).find("label value -1"), std::string::npos);
}

TEST(ServeLabels, BadLbmetaIsRefused) {
  const engine::Volume l = labels([](std::size_t i) { return float(i % 2); });
  EXPECT_NE(refusal(l, {}).find("no LBMETA element"), std::string::npos);
  EXPECT_NE(refusal(l, {{"air", "Seg", 0, {}}, two()[0]}).find("'air' has label value 0"), std::string::npos);
  EXPECT_NE(refusal(l, {two()[0], {"fat", "Seg", 1, {}}}).find("'tissue' and 'fat' have one label value, 1"),
            std::string::npos);
  EXPECT_NE(refusal(l, {two()[0], {"tissue", "Seg", 3, {}}}).find("names two labels 'tissue'"), std::string::npos);
}

TEST(ServeLabels, AnotherGridIsRefusedNamingTheFieldAndBothValues) {
  auto off = [](const std::function<void(engine::Volume&)>& change) {
    engine::Volume l = labels([](std::size_t i) { return float(i % 2); });
    change(l);
    return refusal(l, two());
  };
  EXPECT_NE(off([](engine::Volume& l) { l.grid.dims = {4, 3, 3}; })
                .find("label map dimensions 4 x 3 x 3 are not the volume's 4 x 3 x 2"),
            std::string::npos);
  EXPECT_NE(off([](engine::Volume& l) { l.grid.spacing_m.y = 2.01e-3; }).find("spacing along y is 2.01 mm, the volume's 2 mm"),
            std::string::npos);
  EXPECT_NE(off([](engine::Volume& l) { l.grid.origin_m.z = 30.5e-3; })
                .find("origin along z is 30.5 mm (LPS), the volume's 30 mm"),
            std::string::npos);
  EXPECT_NE(off([](engine::Volume& l) { l.direction = {0, 1, 0, 1, 0, 0, 0, 0, 1}; })
                .find("direction cosine (row 0, column 0) is 0, the volume's 1"),
            std::string::npos);
  // Within the tolerances: taken (float32 mm on the wire).
  EXPECT_EQ(off([](engine::Volume& l) {
              l.grid.spacing_m.x *= 1 + 0.5 * kLabelSpacingTolerance;
              l.grid.origin_m.x += 0.5 * kLabelOriginTolerance * 1.5e-3;
              l.direction[1] = 0.5 * kLabelDirectionTolerance;
            }),
            "");
}

TEST(ServeLabels, LabelMapImageMustBeIntegerAndMayBeNamedLabel) {
  engine::Volume v = frame();
  for (std::size_t i = 0; i < v.voxels.size(); ++i) v.voxels[i] = float(i % 3);
  // int16 (what igtl_test_sender sends), named as Slicer names a labelmap: read
  std::vector<std::uint8_t> b = test::image_of(v, igtl::ImageMessage::ENDIAN_LITTLE, "HeadLabelMap");
  MemorySource src(b);
  Incoming in = read_message(src, MessageLimits{});
  ASSERT_EQ(in.kind, Incoming::Kind::kImage) << in.why;
  const engine::Volume l = label_map_from_image(*in.image);
  EXPECT_EQ(l.voxels, v.voxels);
  EXPECT_EQ(labels_from_image(l, "HeadLabelMap", two(), v, {}).voxels, (std::vector<std::size_t>{8, 8, 8}));
  EXPECT_THROW(volume_from_image(*in.image), engine::VolumeError);  // as a scan: its name says label map
  // float32: refused naming the type
  in.image->SetScalarType(igtl::ImageMessage::TYPE_FLOAT32);
  try {
    label_map_from_image(*in.image);
    ADD_FAILURE() << "a float label map was taken";
  } catch (const engine::VolumeError& e) {
    EXPECT_NE(std::string(e.what()).find("a label map's scalar type is float"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace isotouch::service
