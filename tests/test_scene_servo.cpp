// test_scene_servo.cpp - io/scene_servo.h: a renderer's parameters written as a scene's
// "servo" section read back by the scene parser equal, field by field; the fields a scene
// cannot carry named.
#include <gtest/gtest.h>

#include <string>

#include "isotouch/io/scene.h"
#include "isotouch/io/scene_servo.h"

namespace {
using isotouch::io::parse_scene;
using isotouch::io::servo_section_json;
using isotouch::io::unrecordable_field;
using isotouch::servo::HriParams;

/// A minimal scene (a synthetic sphere) with `hri`'s section, parsed; world_per_device and
/// the isovalue from the scene's own keys.
HriParams read_back(const HriParams& hri) {
  const std::string text = R"({"volume": {"synthetic": "sphere"}, "isovalue": )" + std::to_string(hri.tau) +
                           R"(, "servo": )" + servo_section_json(hri) + "}";
  return parse_scene(text, "written.json").hri;
}

TEST(SceneServo, EveryCarriedFieldReadsBackEqual) {
  HriParams h;
  h.stiffness_n_per_m = 512.25;
  h.damping_n_s_per_m = 0.3;
  h.plane_update_period = 3;
  h.rate_hz = 2000;
  h.force_limit_n = 2.2;
  h.intersection = isotouch::servo::Intersection::kSecant;
  h.intersection_steps = 7;
  h.normal = isotouch::servo::NormalSource::kTrilinearExact;
  h.force_shading = true;
  h.recovery_time_s = 0.035;
  h.friction.mu_s = 0.4, h.friction.mu_d = 0.25, h.friction.viscous_n_s_per_m = 0.1;
  const HriParams p = read_back(h);
  // Against the values set above, not against the writer's own view of them.
  EXPECT_EQ(p.stiffness_n_per_m, 512.25);
  EXPECT_EQ(p.damping_n_s_per_m, 0.3);
  EXPECT_EQ(p.plane_update_period, 3);
  EXPECT_EQ(p.rate_hz, 2000);
  EXPECT_EQ(p.force_limit_n, 2.2);
  EXPECT_EQ(p.intersection, isotouch::servo::Intersection::kSecant);
  EXPECT_EQ(p.intersection_steps, 7);
  EXPECT_EQ(p.normal, isotouch::servo::NormalSource::kTrilinearExact);
  EXPECT_TRUE(p.force_shading);
  EXPECT_EQ(p.recovery_time_s, 0.035);
  EXPECT_EQ(p.friction.mu_s, 0.4);
  EXPECT_EQ(p.friction.mu_d, 0.25);
  EXPECT_EQ(p.friction.viscous_n_s_per_m, 0.1);
  EXPECT_EQ(unrecordable_field(h, p), "");
}

TEST(SceneServo, TheToolAndThePaperVariantReadBackEqual) {
  HriParams tool;
  tool.tool_radius_m = 0.002;
  tool.recovery_time_s = 0.02;
  EXPECT_EQ(read_back(tool).tool_radius_m, 0.002);
  EXPECT_EQ(unrecordable_field(tool, read_back(tool)), "");
  tool.tool_radius_m = 0.0009;  // 0.9 mm * 1e-3 is not 0.0009 in doubles: written as 0.8999999999999999 mm
  EXPECT_EQ(read_back(tool).tool_radius_m, 0.0009);
  // No millimetre value reads back as 0.0045 m (the parser's 1e-3 * mm): named, not silently changed.
  tool.tool_radius_m = 0.0045;
  EXPECT_EQ(unrecordable_field(tool, read_back(tool)), "tool_radius_m 0.0044999999999999997");
  HriParams paper;
  paper.variant = isotouch::servo::Variant::kPaper;
  paper.intersection = isotouch::servo::Intersection::kLinear;
  paper.normal = isotouch::servo::NormalSource::kCentral;
  paper.recovery_time_s = 0;
  const HriParams p = read_back(paper);
  EXPECT_EQ(p.variant, isotouch::servo::Variant::kPaper);
  EXPECT_EQ(unrecordable_field(paper, p), "");
}

TEST(SceneServo, AFieldNoSceneCarriesIsNamedWithItsValue) {
  HriParams h;
  h.recovery_time_s = 0.02;  // the robust variant's scene default
  h.velocity_cutoff_hz = 150;
  EXPECT_EQ(unrecordable_field(h, read_back(h)), "velocity_cutoff_hz 150");
  HriParams m;
  m.recovery_time_s = 0.02;
  m.march_budget = 64;
  EXPECT_EQ(unrecordable_field(m, read_back(m)), "march_budget 64");
  HriParams stiff;
  stiff.recovery_time_s = 0.02;
  HriParams other = stiff;
  other.stiffness_n_per_m = 801;
  EXPECT_EQ(unrecordable_field(other, stiff), "stiffness_n_per_m 801");
}

}  // namespace
