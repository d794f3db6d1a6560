// Scene files: the shipped scenes load; bad ones name the file, the field and the value.
#include <gtest/gtest.h>

#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/scene_fields.h"
#include "isotouch/tests/doc_tables.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

using isotouch::io::load_scene;
using isotouch::io::parse_scene;
using isotouch::io::SceneError;

namespace {
const std::string kScenes = std::string(ISOTOUCH_TEST_DATA) + "/../scenes";

void expect_error(const std::string& text, const std::vector<std::string>& parts) {
  try {
    parse_scene(text, "bad.json");
    FAIL() << "accepted: " << text;
  } catch (const SceneError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("bad.json: ", 0), 0u) << m;
    for (const auto& p : parts) EXPECT_NE(m.find(p), std::string::npos) << "'" << p << "' not in: " << m;
  }
}
}  // namespace

TEST(Scene, ShippedScenesLoad) {
  for (const char* name : {"head", "chest", "sphere", "knot"}) {
    const auto s = load_scene(kScenes + "/" + name + ".json");
    EXPECT_EQ(s.name, name);
    EXPECT_GT(s.hri.stiffness_n_per_m, 0);
    EXPECT_GT(s.hri.force_limit_n, 0);
  }
  const auto head = load_scene(kScenes + "/head.json");
  EXPECT_EQ(head.hri.tau, 1150);
  EXPECT_NE(head.volume_path.find("data/ct-head-headsq/headsq_64x64x93_int16.mhd"), std::string::npos);
  EXPECT_EQ(load_scene(kScenes + "/chest.json").hri.tau, -500);
}

TEST(Scene, RelativeVolumePathIsResolvedAgainstTheSceneFolder) {
  const auto s = parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1})", "/a/b/s.json");
  EXPECT_EQ(s.volume_path, "/a/b/v.mhd");
}

TEST(Scene, Errors) {
  expect_error("{", {"not valid JSON"});
  expect_error(R"({"isovalue": 1})", {"'volume'", "required"});
  expect_error(R"({"volume": {"path": "v.mhd"}})", {"'isovalue'", "required"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"stiffness_n_per_m": -3}})",
               {"'servo.stiffness_n_per_m'", "-3"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"stifness": 3}})",
               {"'servo.stifness'", "unknown field"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": "high"})", {"'isovalue'", "\"high\""});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"plane_update_period": 0}})",
               {"'servo.plane_update_period'", "0"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "inside": "up"})", {"'inside'", "up"});
  expect_error(R"({"volume": {"synthetic": "torus"}, "isovalue": 1})", {"'volume.synthetic'", "torus"});
  expect_error(R"({"volume": {"synthetic": "knot", "dims": [8, 8, 8]}, "isovalue": 0})", {"'volume'", "sphere only"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "script": {"ray_direction": [0, 0, 0]}})",
               {"'script.ray_direction'"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "script": {"ray_direction": [1, 2]}})",
               {"'script.ray_direction'", "[1,2]"});
  expect_error(R"({"volume": {"path": "v.mhd", "synthetic": "sphere"}, "isovalue": 1})", {"exactly one"});
  // The paper variant cannot be asked for another intersection or normal rule (it would be
  // silently overridden by Figure 2 as printed).
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"variant": "paper", "normal": "samples"}})",
               {"'servo.normal'", "paper", "samples"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"variant": "paper", "intersection": "secant"}})",
               {"'servo.intersection'", "secant"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"intersection": "newton"}})",
               {"'servo.intersection'", "newton"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"friction": {"mu_s": 0.2, "mu_d": 0.5}}})",
               {"'servo.friction.mu_d'", "0.5"});
}

// The burr scenes withdraw the burr along the channel it drilled; the others lift straight.
TEST(Scene, LiftRetraceIsAFlagOfTheScript) {
  EXPECT_TRUE(load_scene(kScenes + "/drill-burr.json").script.lift_retrace);
  EXPECT_TRUE(load_scene(kScenes + "/drill-vault.json").script.lift_retrace);
  EXPECT_FALSE(load_scene(kScenes + "/drill-skull.json").script.lift_retrace);
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "script": {"lift_retrace": 1}})",
               {"'script.lift_retrace'", "true or false", "1"});
}

TEST(Scene, ServoOptions) {
  const auto s = parse_scene(R"({"volume": {"synthetic": "knot"}, "isovalue": 0,
    "servo": {"intersection": "secant", "intersection_steps": 6, "normal": "central", "force_shading": true,
              "recovery_time_s": 0.02, "friction": {"mu_s": 0.4, "mu_d": 0.3, "viscous_n_s_per_m": 2}}})", "s.json");
  EXPECT_EQ(s.hri.intersection, isotouch::servo::Intersection::kSecant);
  EXPECT_EQ(s.hri.intersection_steps, 6);
  EXPECT_EQ(s.hri.normal, isotouch::servo::NormalSource::kCentral);
  EXPECT_TRUE(s.hri.force_shading);
  EXPECT_DOUBLE_EQ(s.hri.recovery_time_s, 0.02);
  EXPECT_DOUBLE_EQ(s.hri.friction.mu_d, 0.3);
  EXPECT_EQ(s.synthetic.kind, "knot");
}

// ---- duplicate keys, overflowing numbers, ray origin range --------------------------
TEST(Scene, SphericalTool) {
  const std::string base = R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": )";
  EXPECT_EQ(parse_scene(base + "{}}", "s.json").hri.tool_radius_m, 0.0);  // the point by default
  EXPECT_DOUBLE_EQ(parse_scene(base + R"({"tool": {"radius_mm": 4.5}}})", "s.json").hri.tool_radius_m, 0.0045);
  expect_error(base + R"({"tool": {"radius_mm": -1}}})", {"'servo.tool.radius_mm'", "-1"});
  expect_error(base + R"({"tool": {"radius_mm": "big"}}})", {"'servo.tool.radius_mm'", "\"big\""});
  expect_error(base + R"({"tool": {"radius": 2}}})", {"'servo.tool.radius'", "unknown"});
  expect_error(base + R"({"tool": 2}})", {"'servo.tool'", "2"});
  expect_error(base + R"({"variant": "paper", "tool": {"radius_mm": 2}}})", {"'servo.tool.radius_mm'", "paper"});
  expect_error(base + R"({"force_shading": true, "tool": {"radius_mm": 2}}})", {"'servo.tool.radius_mm'", "shading"});
  EXPECT_EQ(parse_scene(base + R"({"variant": "paper", "tool": {"radius_mm": 0}}})", "s.json").hri.tool_radius_m, 0.0);
}

// The button's carve or drill brush is felt as the spherical tool of its radius unless the
// scene gives the tool or keeps the point; an add brush, or no button, leaves the point.
TEST(Scene, BurrIsTheTool) {
  auto scene = [](const std::string& servo, const std::string& kind, const std::string& button = "[[0.5, 1]]") {
    return R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "engine": {"mode": "sparse"}, "servo": )" + servo +
           R"(, "edits": {"brush": {"kind": ")" + kind + R"(", "radius_mm": 3}, "button": )" + button + "}}";
  };
  const auto drill = parse_scene(scene("{}", "drill"), "s.json");
  EXPECT_DOUBLE_EQ(drill.hri.tool_radius_m, 0.003);
  EXPECT_TRUE(drill.tool_from_brush);
  EXPECT_DOUBLE_EQ(parse_scene(scene("{}", "carve"), "s.json").hri.tool_radius_m, 0.003);
  EXPECT_EQ(parse_scene(scene("{}", "add"), "s.json").hri.tool_radius_m, 0.0);
  EXPECT_EQ(parse_scene(scene("{}", "drill", "[]"), "s.json").hri.tool_radius_m, 0.0);
  const auto point = parse_scene(scene(R"({"tool": {"point": true}})", "drill"), "s.json");
  EXPECT_EQ(point.hri.tool_radius_m, 0.0);
  EXPECT_TRUE(point.point_probe);
  const auto given = parse_scene(scene(R"({"tool": {"radius_mm": 2}})", "drill"), "s.json");
  EXPECT_DOUBLE_EQ(given.hri.tool_radius_m, 0.002);
  EXPECT_FALSE(given.tool_from_brush);
  expect_error(scene(R"({"tool": {"point": true, "radius_mm": 2}})", "drill"), {"'servo.tool.point'", "both"});
  expect_error(scene(R"({"tool": {"point": 1}})", "drill"), {"'servo.tool.point'", "true or false"});
  expect_error(scene(R"({"variant": "paper"})", "drill"), {"'edits.brush'", "point"});
  EXPECT_EQ(parse_scene(scene(R"({"variant": "paper", "tool": {"point": true}})", "drill"), "s.json").hri.tool_radius_m, 0.0);
}

// The brush that cuts at the VHIP: the tool's radius plus half the largest voxel spacing
// (the head CT's 3.2 x 3.2 x 1.5 mm: 4.5 + 1.6 mm); a point keeps the brush's radius.
TEST(Scene, CuttingBrushIsTheToolsRadius) {
  isotouch::engine::Volume vol;
  vol.grid.spacing_m = {3.2e-3, 3.2e-3, 1.5e-3};
  isotouch::io::Scene s;
  isotouch::io::BrushSpec b;
  b.radius_mm = 4.5;
  EXPECT_DOUBLE_EQ(isotouch::run::brush_at_tool(s, vol, b).radius_mm, 4.5);
  s.hri.tool_radius_m = 4.5e-3;
  EXPECT_NEAR(isotouch::run::tool_brush_margin_m(vol), 1.6e-3, 1e-12);
  EXPECT_NEAR(isotouch::run::brush_at_tool(s, vol, b).radius_mm, 6.1, 1e-9);
}

TEST(Scene, DuplicateKeyIsAnError) {
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"stiffness_n_per_m": 800,
                   "stiffness_n_per_m": 80000}})",
               {"'servo.stiffness_n_per_m'", "twice"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "isovalue": 2})", {"'isovalue'", "twice"});
  // The same key in different objects is fine.
  EXPECT_NO_THROW(parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1,
                                  "servo": {"damping_n_s_per_m": 1}, "device": {"damping_n_s_per_m": 1}})",
                              "ok.json"));
}

TEST(Scene, NumberOverflowNamesTheFile) {
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1e999})", {"not valid JSON", "1e999", "must be finite"});
}

TEST(Scene, JsonErrorsSayWhatToDoWithoutTheParsersId) {
  for (const char* text : {"{", R"({"volume": {"path": "v.mhd"} "isovalue": 1})", R"({"isovalue": 1e400})"}) {
    try {
      parse_scene(text, "bad.json");
      FAIL() << "accepted: " << text;
    } catch (const SceneError& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.find("[json.exception"), std::string::npos) << m;
      EXPECT_TRUE(m.find("line 1, column") != std::string::npos || m.find("must be finite") != std::string::npos) << m;
    }
  }
}

// The force is stiffness x the hand's travel, the probe's depth / workspace_scale: 1e-9
// turns every touch into the force limit, 1000 leaves no force to feel. Refused, saying so.
TEST(Scene, WorkspaceScaleOutsideWhatAHandCanFeelIsRefused) {
  const std::string base = R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "device": {"workspace_scale": )";
  expect_error(base + "1e-9}}", {"'device.workspace_scale'", "[0.0001, 10]", "1e-09", "force limit"});
  expect_error(base + "1000}}", {"'device.workspace_scale'", "[0.0001, 10]", "1000", "too little force"});
  EXPECT_EQ(parse_scene(base + "0.0001}}", "ok.json").workspace_scale, 1e-4);
  EXPECT_EQ(parse_scene(base + "10}}", "ok.json").workspace_scale, 10.0);
}

// Above Colgate and Schenkel's bound 2 (b - |B|) / T the wall may buzz: refused unless the
// scene opts in with servo.allow_unstable_stiffness.
TEST(Scene, StiffnessAboveTheStabilityBoundNeedsTheSceneToSaySo) {
  // b = 0.01 + 5 N s/m (the device defaults), B = 1 N s/m, T = 1 ms: K_max = 8020 N/m.
  const std::string base = R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "servo": {"stiffness_n_per_m": )";
  expect_error(base + "8021}}", {"'servo.stiffness_n_per_m'", "8020", "8021", "allow_unstable_stiffness"});
  EXPECT_EQ(parse_scene(base + "8019}}", "ok.json").hri.stiffness_n_per_m, 8019.0);
  const auto s = parse_scene(base + R"(1e6, "allow_unstable_stiffness": true}})", "ok.json");
  EXPECT_EQ(s.hri.stiffness_n_per_m, 1e6);
  EXPECT_TRUE(s.allow_unstable_stiffness);
  // The bound follows the rate: 800 N/m at 10 Hz (K_max = 80.2 N/m) is refused too.
  expect_error(base + R"(800, "rate_hz": 10}})", {"'servo.stiffness_n_per_m'", "80.2"});
}

// The live servo's passivity controller: off unless the scene says so; a non-boolean is refused.
TEST(Scene, PassivityControlIsOffUnlessTheSceneSaysSo) {
  const std::string base = R"({"volume": {"path": "v.mhd"}, "isovalue": 1)";
  EXPECT_FALSE(parse_scene(base + "}", "ok.json").passivity_control);
  EXPECT_TRUE(parse_scene(base + R"(, "servo": {"passivity_control": true}})", "ok.json").passivity_control);
  expect_error(base + R"(, "servo": {"passivity_control": 1}})", {"'servo.passivity_control'"});
}

// The link's stiffness check (`--haptic igtl:`, issue 67): a round trip beyond the stream's
// hold [ms in the file, s parsed] and whether the peer runs the passivity controller.
TEST(Scene, LinkRoundTripAndThePeersControllerAreTheScenesToSay) {
  const std::string base = R"({"volume": {"path": "v.mhd"}, "isovalue": 1)";
  const auto plain = parse_scene(base + "}", "ok.json");
  EXPECT_EQ(plain.link_round_trip_s, 0.0);
  EXPECT_FALSE(plain.link_passivity_control);
  const auto said =
      parse_scene(base + R"(, "device": {"link_round_trip_ms": 12.5, "link_passivity_control": true}})", "ok.json");
  EXPECT_DOUBLE_EQ(said.link_round_trip_s, 0.0125);
  EXPECT_TRUE(said.link_passivity_control);
  expect_error(base + R"(, "device": {"link_round_trip_ms": -1}})", {"'device.link_round_trip_ms'", "-1"});
  expect_error(base + R"(, "device": {"link_passivity_control": "yes"}})", {"'device.link_passivity_control'"});
}

TEST(Scene, RayOriginFracRange) {
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "script": {"ray_origin_frac": [0.5, 0.5, -1e6]}})",
               {"'script.ray_origin_frac'", "[-2, 3]", "-1000000"});
  EXPECT_NO_THROW(parse_scene(
      R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "script": {"ray_origin_frac": [-2, 3, 0.5]}})", "ok.json"));
}

TEST(Scene, DeviceTooLightToSimulate) {
  // 1e-4 kg is simulated (the device raises its substeps); 1e-9 kg would need > 10000.
  EXPECT_NO_THROW(parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "device": {"mass_kg": 1e-4}})", "ok.json"));
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "device": {"mass_kg": 1e-9}})",
               {"'device.mass_kg'", "1e-09", "at least"});
}

TEST(Scene, SyntheticSpacingRange) {
  // spacing_m 1e-12 gave a run with no contact tick that exited 0 with a zero error.
  const std::string pre = R"({"volume": {"synthetic": "sphere", "spacing_m": )";
  const std::string post = R"(}, "isovalue": 0})";
  expect_error(pre + "1e-12" + post, {"'volume.spacing_m'", "[1e-6, 0.1]", "1e-12"});
  expect_error(pre + "0.5" + post, {"'volume.spacing_m'", "[1e-6, 0.1]", "0.5"});
  EXPECT_NO_THROW(parse_scene(pre + "1e-6" + post, "ok.json"));
  EXPECT_NO_THROW(parse_scene(pre + "0.1" + post, "ok.json"));
}

// ---- the "engine" section --------------------------------------------------
namespace {
std::string with_engine(const std::string& engine) {
  return R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "engine": )" + engine + "}";
}
}  // namespace

TEST(Scene, EngineDefaultsAreTodaysGradientOnly) {
  const auto s = parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1})", "ok.json");
  ASSERT_EQ(s.engine.passes.size(), 1u);
  EXPECT_EQ(s.engine.passes[0].kind, "gradient");
  EXPECT_EQ(s.engine.mode, "sparse");
  EXPECT_EQ(s.engine.samples, "fp32");
}

TEST(Scene, EnginePassesWithParameters) {
  const auto s = parse_scene(with_engine(R"({"passes": [{"gaussian": {"sigma_mm": 1.5}}, {"closing": {"radius_mm": 0}},
      "gradient", {"brick_minmax": {"halo": 2}}], "mode": "dense", "samples": "fp32"})"), "ok.json");
  ASSERT_EQ(s.engine.passes.size(), 4u);
  EXPECT_EQ(s.engine.passes[0].kind, "gaussian");
  EXPECT_DOUBLE_EQ(s.engine.passes[0].sigma_mm, 1.5);
  EXPECT_EQ(s.engine.passes[1].kind, "closing");
  EXPECT_DOUBLE_EQ(s.engine.passes[1].radius_mm, 0.0);
  EXPECT_EQ(s.engine.passes[2].kind, "gradient");
  EXPECT_EQ(s.engine.passes[3].halo, 2);
  EXPECT_EQ(s.engine.mode, "dense");
  const auto c = parse_scene(with_engine(R"({"samples": "unorm16"})"), "ok.json");
  EXPECT_EQ(c.engine.samples, "unorm16");
  EXPECT_EQ(c.engine.mode, "sparse");
}

TEST(Scene, EngineErrorsNameTheField) {
  expect_error(with_engine(R"({"pases": []})"), {"'engine.pases'", "unknown field"});
  expect_error(with_engine(R"({"passes": []})"), {"'engine.passes'", "non-empty"});
  expect_error(with_engine(R"({"passes": "gradient"})"), {"'engine.passes'", "\"gradient\""});
  expect_error(with_engine(R"({"passes": ["median", "gradient"]})"), {"'engine.passes[0]'", "unknown pass", "median"});
  expect_error(with_engine(R"({"passes": [{"gaussian": {"sigma_mm": 0}}, "gradient"]})"),
               {"'engine.passes[0].gaussian.sigma_mm'", "got 0"});
  expect_error(with_engine(R"({"passes": [{"gaussian": {"sigma_mm": -1}}, "gradient"]})"),
               {"'engine.passes[0].gaussian.sigma_mm'", "-1"});
  expect_error(with_engine(R"({"passes": ["gaussian", "gradient"]})"), {"'engine.passes[0].gaussian.sigma_mm'", "required"});
  expect_error(with_engine(R"({"passes": [{"gaussian": {"sigma": 1}}, "gradient"]})"),
               {"'engine.passes[0].gaussian.sigma'", "unknown field"});
  expect_error(with_engine(R"({"passes": [{"closing": {"radius_mm": -2}}, "gradient"]})"),
               {"'engine.passes[0].closing.radius_mm'", "-2"});
  expect_error(with_engine(R"({"passes": ["gradient", {"brick_minmax": {"halo": 9}}]})"),
               {"'engine.passes[1].brick_minmax.halo'", "9"});
  expect_error(with_engine(R"({"passes": [{"gradient": {"x": 1}}]})"), {"'engine.passes[0].gradient'", "no parameters"});
  expect_error(with_engine(R"({"passes": [{"gaussian": {"sigma_mm": 1}, "closing": {"radius_mm": 1}}, "gradient"]})"),
               {"'engine.passes[0]'", "one name"});
  expect_error(with_engine(R"({"passes": [{"gaussian": {"sigma_mm": 1}}]})"), {"'engine.passes'", "must include \"gradient\""});
  expect_error(with_engine(R"({"passes": ["gradient", {"gaussian": {"sigma_mm": 1}}]})"),
               {"'engine.passes[1]'", "after \"gradient\""});
  expect_error(with_engine(R"({"mode": "bricked"})"), {"'engine.mode'", "bricked"});
  expect_error(with_engine(R"({"samples": "fp8"})"), {"'engine.samples'", "fp8"});
  expect_error(with_engine(R"({"mode": "dense", "samples": "fp16"})"), {"'engine.samples'", "fp16", "sparse"});
  expect_error(with_engine(R"([1])"), {"'engine'", "object"});
}

TEST(Scene, EnginePassListCheckedByTheEngine) {
  // Structure rules are engine::validate_passes's (gradient and brick_minmax at most once),
  // reported as a scene error naming the file and field before anything runs.
  const auto twice = parse_scene(with_engine(R"({"passes": ["gradient", "gradient"]})"), "bad.json");
  try {
    (void)isotouch::run::scene_passes(twice);
    FAIL() << "gradient twice accepted";
  } catch (const SceneError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("bad.json: field 'engine.passes': ", 0), 0u) << m;
    EXPECT_NE(m.find("pass 1 (gradient)"), std::string::npos) << m;
  }
  const auto ok = parse_scene(with_engine(R"({"passes": [{"gaussian": {"sigma_mm": 2}}, {"closing": {"radius_mm": 1}},
      "gradient"], "samples": "fp16"})"), "ok.json");
  const auto p = isotouch::run::scene_passes(ok);
  ASSERT_EQ(p.size(), 3u);
  EXPECT_EQ(p[0].kind, isotouch::engine::PassKind::Gaussian);
  EXPECT_DOUBLE_EQ(p[0].sigma_mm, 2.0);
  EXPECT_EQ(p[1].kind, isotouch::engine::PassKind::Closing);
  EXPECT_DOUBLE_EQ(p[1].radius_mm, 1.0);
  EXPECT_EQ(p[2].kind, isotouch::engine::PassKind::Gradient);
  EXPECT_EQ(isotouch::run::scene_sample_format(ok), isotouch::core::SampleFormat::kFp16);
}

// The drill's rate as a fraction of the material-to-empty range per N s: the same removal
// on 8-bit and HU data (rate in value units = fraction x |material - empty|); "rate" and
// "removal_per_n_s" together are refused.
TEST(Scene, DrillRemovalPerNsMeansTheSameOnEveryVolume) {
  const auto s = parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "edits": {
      "brush": {"kind": "drill", "removal_per_n_s": 0.25}}})", "ok.json");
  EXPECT_EQ(s.edits.brush.removal_per_n_s, 0.25);
  isotouch::session::BrushTargets hu{3071.0f, -1024.0f, 4095.0f}, u8{255.0f, 0.0f, 255.0f};
  EXPECT_DOUBLE_EQ(isotouch::run::drill_rate(s.edits.brush, hu), 0.25 * 4095.0);
  EXPECT_DOUBLE_EQ(isotouch::run::drill_rate(s.edits.brush, u8), 0.25 * 255.0);
  const auto v = parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "edits": {
      "brush": {"kind": "drill", "rate": 700}}})", "ok.json");
  EXPECT_DOUBLE_EQ(isotouch::run::drill_rate(v.edits.brush, u8), 700.0);  // value units as given
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "edits": {
      "brush": {"kind": "drill", "rate": 700, "removal_per_n_s": 0.1}}})",
               {"edits.brush.removal_per_n_s", "not both"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "edits": {
      "brush": {"kind": "drill", "removal_per_n_s": -1}}})",
               {"edits.brush.removal_per_n_s"});
}

// The "edits" section: brush defaults, timeline, button, undo limit.
TEST(Scene, EditsSectionParses) {
  const auto s = parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "edits": {
      "brush": {"kind": "drill", "radius_mm": 3, "force_threshold_n": 0.7, "rate": 500, "density_scale": 20},
      "every_ticks": 5, "button": [[0.5, 1.0], [2, 3]], "history_limit_mib": 8,
      "timeline": [{"t_s": 2.5, "kind": "undo"},
                   {"t_s": 1.5, "kind": "carve", "at": [1, 2, 3], "radius_mm": 4, "strength": 50, "duration_s": 0.2},
                   {"t_s": 1.5, "kind": "add", "at": "vhip", "material": 9}]}})",
                             "ok.json");
  ASSERT_TRUE(s.edits.present);
  EXPECT_EQ(s.edits.brush.kind, "drill");
  EXPECT_EQ(s.edits.brush.radius_mm, 3);
  EXPECT_EQ(s.edits.brush.force_threshold_n, 0.7);
  EXPECT_EQ(s.edits.brush.rate, 500);
  EXPECT_EQ(s.edits.brush.density_scale, 20);
  EXPECT_EQ(s.edits.every_ticks, 5);
  EXPECT_EQ(s.edits.history_limit_mib, 8);
  ASSERT_EQ(s.edits.button_down.size(), 2u);
  EXPECT_EQ(s.edits.button_down[1][0], 2);
  EXPECT_EQ(s.edits.button_down[1][1], 3);
  ASSERT_EQ(s.edits.timeline.size(), 3u);
  // Sorted by time, entries at one time in file order; overrides on the defaults.
  EXPECT_EQ(s.edits.timeline[0].kind, "carve");
  EXPECT_EQ(s.edits.timeline[0].index, 1);
  EXPECT_FALSE(s.edits.timeline[0].at_vhip);
  EXPECT_DOUBLE_EQ(s.edits.timeline[0].at_m.z, 3e-3);  // mm in the file, m here
  EXPECT_EQ(s.edits.timeline[0].brush.radius_mm, 4);
  EXPECT_EQ(s.edits.timeline[0].brush.strength, 50);
  EXPECT_EQ(s.edits.timeline[0].brush.rate, 500);  // inherited from edits.brush
  EXPECT_EQ(s.edits.timeline[0].duration_s, 0.2);
  EXPECT_EQ(s.edits.timeline[1].kind, "add");
  EXPECT_TRUE(s.edits.timeline[1].at_vhip);
  EXPECT_TRUE(s.edits.timeline[1].brush.has_material);
  EXPECT_EQ(s.edits.timeline[1].brush.material, 9);
  EXPECT_EQ(s.edits.timeline[2].kind, "undo");
  EXPECT_FALSE(parse_scene(R"({"volume": {"path": "v.mhd"}, "isovalue": 1})", "x.json").edits.present);
  EXPECT_TRUE(load_scene(kScenes + "/drill-skull.json").edits.present);
}

TEST(Scene, EditsErrorsNameTheField) {
  const std::string head = R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "edits": )";
  expect_error(head + R"({"brush": {"kind": "chisel"}}})", {"'edits.brush.kind'", "chisel"});
  expect_error(head + R"({"brush": {"radius_mm": 0}}})", {"'edits.brush.radius_mm'", "0"});
  expect_error(head + R"({"brush": {"kind": "smooth", "strength": 2}}})", {"'edits.brush.strength'", "2"});
  expect_error(head + R"({"brush": {"falloff": 1.5}}})", {"'edits.brush.falloff'", "1.5"});
  expect_error(head + R"({"brush": {"force_n": 1}}})", {"'edits.brush.force_n'", "unknown field"});
  expect_error(head + R"({"every_ticks": 0}})", {"'edits.every_ticks'", "0"});
  expect_error(head + R"({"history_limit_mib": -1}})", {"'edits.history_limit_mib'", "-1"});
  expect_error(head + R"({"button": [[1, 0.5]]}})", {"'edits.button[0]'", "[1,0.5]"});
  expect_error(head + R"({"button": [[0, 2], [1, 3]]}})", {"'edits.button[1]'", "overlap"});
  expect_error(head + R"({"button": [0, 1]}})", {"'edits.button[0]'", "[t0, t1]"});
  expect_error(head + R"({"timeline": [{"kind": "carve", "at": [0, 0, 0]}]}})", {"'edits.timeline[0].t_s'", "required"});
  expect_error(head + R"({"timeline": [{"t_s": 0, "kind": "carve"}]}})", {"'edits.timeline[0].at'", "required"});
  expect_error(head + R"({"timeline": [{"t_s": 0, "kind": "carve", "at": "hip"}]}})", {"'edits.timeline[0].at'", "hip"});
  expect_error(head + R"({"timeline": [{"t_s": 0, "kind": "carve", "at": [1, 2]}]}})", {"'edits.timeline[0].at'", "[1,2]"});
  expect_error(head + R"({"timeline": [{"t_s": 1, "kind": "undo"}, {"t_s": -1, "kind": "undo"}]}})",
               {"'edits.timeline[1].t_s'", "-1"});
  expect_error(head + R"({"timeline": [{"t_s": 1, "kind": "undo", "radius_mm": 2}]}})",
               {"'edits.timeline[0].radius_mm'", "unknown field"});
  expect_error(head + R"({"timeline": [{"t_s": 1, "kind": "zap", "at": "vhip"}]}})", {"'edits.timeline[0].kind'", "zap"});
  expect_error(head + R"({"timeline": [{"t_s": 1, "kind": "drill", "at": "vhip", "force_n": -2}]}})",
               {"'edits.timeline[0].force_n'", "-2"});
  expect_error(head + R"({"brush": {}, "undo": 3}})", {"'edits.undo'", "unknown field"});
  expect_error(R"({"volume": {"path": "v.mhd"}, "isovalue": 1, "engine": {"mode": "dense"}, "edits": {}})",
               {"'edits'", "sparse", "dense"});
}

// ---- the docs' field tables against the parser's table ----------------------------------


namespace {

// A documented field's unit, range and default cells ("" where the table has no such column).
using DocRow = std::array<std::string, 3>;
using DocRows = std::map<std::string, DocRow>;  // "section.key" -> its cells

// kSceneFields as the docs should show them.
DocRows table_rows() {
  DocRows rows;
  for (const isotouch::io::SceneField& f : isotouch::io::kSceneFields)
    rows[std::string(f.section) + "." + std::string(f.key)] = {std::string(f.unit), std::string(f.range),
                                                                std::string(f.default_text)};
  return rows;
}

// The cell of `row` under the header `name` ("" when the table has no such column).
std::string cell(const std::vector<std::string>& head, const std::vector<std::string>& row, const std::string& name) {
  for (std::size_t c = 0; c < head.size() && c < row.size(); ++c)
    if (head[c] == name) return row[c];
  return "";
}

// Every field table of the scene format in docs/user-guide.md, and the passes' parameters.
DocRows documented_rows(const std::string& doc) {
  const std::map<std::string, std::string> anchors{
      {"", "### Top level"}, {"volume", "### `volume`"}, {"servo", "### `servo`"},
      {"servo.friction", "`servo.friction` ("}, {"servo.tool", "`servo.tool` ("}, {"device", "### `device`"},
      {"script", "### `script`"}, {"engine", "### `engine`"}, {"edits", "### `edits`"},
      {"edits.brush", "A brush (in `edits.brush`"}, {"edits.timeline", "A timeline entry is"},
      {"outputs", "### `outputs`"}, {"materials", "### `materials`"},
      {"materials.list", "A material (in `materials.list`"}};
  DocRows rows;
  for (const auto& [section, anchor] : anchors) {
    const auto table = isotouch::test::table_after(doc, anchor);
    EXPECT_GE(table.size(), 2u) << "no table after '" << anchor << "'";
    if (table.size() < 2) continue;
    EXPECT_EQ(table[0][0], "field") << anchor;
    for (std::size_t i = 1; i < table.size(); ++i)
      for (const std::string& key : isotouch::test::code_names(table[i][0]))
        rows[section + "." + key] = {cell(table[0], table[i], "unit"), cell(table[0], table[i], "range"),
                                     cell(table[0], table[i], "default")};
  }
  // | pass | parameter | unit | range | default |: a pass's parameters are section
  // "engine.passes.NAME" ("none": it takes none).
  const auto passes = isotouch::test::table_after(doc, "A pass is its name");
  EXPECT_GE(passes.size(), 2u) << "no passes table";
  for (std::size_t i = 1; i < passes.size(); ++i)
    for (const std::string& pass : isotouch::test::code_names(passes[i][0]))
      for (const std::string& key : isotouch::test::code_names(passes[i][1]))
        rows["engine.passes." + pass + "." + key] = {cell(passes[0], passes[i], "unit"),
                                                     cell(passes[0], passes[i], "range"),
                                                     cell(passes[0], passes[i], "default")};
  return rows;
}

// Every table of the scene format in docs/user-guide.md lists exactly the fields of
// io::kSceneFields (which io/scene.cpp reads for its keys, ranges and defaults), each with
// the table's unit, range and default: a field added to either, or a range or default
// changed in either, fails here until the other says the same.
TEST(SceneDocs, FieldTablesListExactlyTheParsersFields) {
  const std::string doc = isotouch::test::user_guide();
  ASSERT_FALSE(doc.empty()) << "docs/user-guide.md not found";
  const DocRows documented = documented_rows(doc), table = table_rows();
  for (const auto& [field, row] : table) {
    const auto d = documented.find(field);
    if (d == documented.end()) ADD_FAILURE() << field << ": in io/scene_fields.h but not in docs/user-guide.md";
    else EXPECT_EQ(d->second, row) << field << ": docs/user-guide.md against io/scene_fields.h";
  }
  for (const auto& [field, row] : documented)
    EXPECT_TRUE(table.count(field)) << field << ": in docs/user-guide.md but not in io/scene_fields.h";
}

// A table's numeric ranges are all readable as numbers, so the parser can check them.
TEST(SceneDocs, NumericRangesParse) {
  int numeric = 0;
  for (const isotouch::io::SceneField& f : isotouch::io::kSceneFields) {
    const std::string_view r = f.range;
    const bool looks_numeric = !r.empty() && (r[0] == '[' || r[0] == '(' || r.rfind("integer [", 0) == 0);
    if (!looks_numeric) continue;
    ++numeric;
    EXPECT_TRUE(isotouch::io::field_range(r)) << f.section << "." << f.key << ": '" << r << "'";
  }
  EXPECT_GE(numeric, 40);
}

// The scene text with `section_json` (e.g. "\"servo\": {...}") added to a minimal sphere scene.
std::string sphere_with(const std::string& section_json) {
  return R"({"volume": {"synthetic": "sphere"}, "isovalue": 0, "inside": "below", )" + section_json + "}";
}

// The parser refuses and accepts at the table's range, whatever the range is: each field's
// ends (open or closed) and just beyond them, read from kSceneFields.
TEST(SceneDocs, ParserChecksTheTablesRanges) {
  struct Case {
    std::string_view section, key;
    std::string json;  // the scene's section with "V" where the value goes
  };
  const Case cases[] = {
      {"script", "hold_s", R"("script": {"hold_s": V})"},
      {"servo", "force_limit_n", R"("servo": {"force_limit_n": V})"},
      {"servo", "intersection_steps", R"("servo": {"intersection_steps": V})"},
      {"servo.friction", "mu_s", R"("servo": {"friction": {"mu_s": V}})"},
      {"servo.tool", "radius_mm", R"("servo": {"tool": {"radius_mm": V}})"},
      {"device", "coulomb_friction_n", R"("device": {"coulomb_friction_n": V})"},
      {"edits.brush", "falloff", R"("edits": {"brush": {"falloff": V}})"},
      {"edits.timeline", "t_s", R"("edits": {"timeline": [{"t_s": V, "kind": "carve", "at": [0, 0, 0]}]})"},
      {"engine.passes.brick_minmax", "halo", R"("engine": {"passes": [{"brick_minmax": {"halo": V}}, "gradient"]})"},
  };
  for (const Case& c : cases) {
    const isotouch::io::SceneField* f = isotouch::io::scene_field(c.section, c.key);
    ASSERT_TRUE(f) << c.section << "." << c.key;
    const auto range = isotouch::io::field_range(f->range);
    ASSERT_TRUE(range) << f->range;
    const double step = range->integer ? 1 : std::max(std::abs(range->hi), 1.0) * 1e-6;
    const auto scene = [&](double v) {
      std::ostringstream num;
      num.precision(17);
      num << v;
      std::string j = c.json;
      j.replace(j.find('V'), 1, num.str());
      return sphere_with(j);
    };
    const auto accepts = [&](double v) {
      try {
        parse_scene(scene(v), "bad.json");
        return true;
      } catch (const SceneError& e) {
        EXPECT_NE(std::string(e.what()).find("must be " + range->phrase()), std::string::npos) << e.what();
        return false;
      }
    };
    EXPECT_EQ(accepts(range->lo), !range->lo_open) << f->key << " = " << range->lo;
    EXPECT_FALSE(accepts(range->lo - step)) << f->key << " = " << range->lo - step;
    EXPECT_TRUE(accepts(range->lo + step)) << f->key << " = " << range->lo + step;
    EXPECT_EQ(accepts(range->hi), !range->hi_open) << f->key << " = " << range->hi;
    EXPECT_FALSE(accepts(range->hi + step)) << f->key << " = " << range->hi + step;
  }
}

// A field left out takes the table's default (as the docs show it): every field whose
// default is a number, read back from the parsed scene.
TEST(SceneDocs, AbsentFieldsTakeTheTablesDefaults) {
  const auto s = parse_scene(
      sphere_with(R"("servo": {"friction": {}, "tool": {}}, "engine": {"passes": [{"brick_minmax": {}}, "gradient"]},)"
                  R"( "edits": {"timeline": [{"t_s": 1, "kind": "carve", "at": "vhip"}]},)"
                  R"( "materials": {"list": [{"name": "a", "range": [0, 1]}]})"),
      "ok.json");
  const std::map<std::string, double> parsed{
      {"volume.spacing_m", s.synthetic.spacing_m}, {"volume.radius_vox", s.synthetic.radius_vox},
      {"servo.stiffness_n_per_m", s.hri.stiffness_n_per_m}, {"servo.damping_n_s_per_m", s.hri.damping_n_s_per_m},
      {"servo.plane_update_period", s.hri.plane_update_period}, {"servo.rate_hz", s.hri.rate_hz},
      {"servo.force_limit_n", s.hri.force_limit_n}, {"servo.intersection_steps", s.hri.intersection_steps},
      {"servo.friction.mu_s", s.hri.friction.mu_s}, {"servo.friction.mu_d", s.hri.friction.mu_d},
      {"servo.friction.viscous_n_s_per_m", s.hri.friction.viscous_n_s_per_m},
      {"servo.tool.radius_mm", s.hri.tool_radius_m * 1e3},
      {"device.mass_kg", s.device.mass_kg}, {"device.damping_n_s_per_m", s.device.damping_n_s_per_m},
      {"device.coulomb_friction_n", s.device.coulomb_friction_n},
      {"device.encoder_resolution_m", s.device.encoder_resolution_m}, {"device.force_max_n", s.device.force_max_n},
      {"device.hand_stiffness_n_per_m", s.device.hand_stiffness_n_per_m},
      {"device.hand_damping_n_s_per_m", s.device.hand_damping_n_s_per_m}, {"device.substeps", s.device.substeps},
      {"device.workspace_scale", s.workspace_scale}, {"device.link_max_force_n", s.link_max_force_n},
      {"device.link_round_trip_ms", s.link_round_trip_s * 1e3},
      {"script.approach_distance_m", s.script.approach_distance_m},
      {"script.approach_speed_m_s", s.script.approach_speed_m_s}, {"script.press_depth_m", s.script.press_depth_m},
      {"script.press_speed_m_s", s.script.press_speed_m_s}, {"script.hold_s", s.script.hold_s},
      {"script.stroke_length_m", s.script.stroke_length_m}, {"script.stroke_speed_m_s", s.script.stroke_speed_m_s},
      {"script.rest_s", s.script.rest_s}, {"script.press_force_fraction", s.script.press_force_fraction},
      {"engine.passes.brick_minmax.halo", s.engine.passes.at(0).halo},
      {"edits.every_ticks", s.edits.every_ticks}, {"edits.history_limit_mib", s.edits.history_limit_mib},
      {"edits.brush.radius_mm", s.edits.brush.radius_mm}, {"edits.brush.strength", s.edits.brush.strength},
      {"edits.brush.falloff", s.edits.brush.falloff}, {"edits.brush.force_threshold_n", s.edits.brush.force_threshold_n},
      {"edits.brush.rate", s.edits.brush.rate}, {"edits.timeline.duration_s", s.edits.timeline.at(0).duration_s},
      {"materials.list.stiffness_n_per_m", s.materials.list.at(0).stiffness_n_per_m},
      {"materials.list.mu_s", s.materials.list.at(0).mu_s}, {"materials.list.mu_d", s.materials.list.at(0).mu_d},
      {"materials.list.rate", s.materials.list.at(0).rate},
      {"materials.list.density_scale", s.materials.list.at(0).density_scale},
      {"materials.list.margin_mm", s.materials.list.at(0).margin_mm},
  };
  for (const isotouch::io::SceneField& f : isotouch::io::kSceneFields) {
    const auto def = isotouch::io::plain_number(f.default_text);
    if (!def) continue;
    const std::string name = std::string(f.section) + "." + std::string(f.key);
    const auto it = parsed.find(name);
    if (it == parsed.end()) ADD_FAILURE() << name << ": a numeric default this test does not read back";
    else EXPECT_DOUBLE_EQ(it->second, *def) << name;
  }
}

}  // namespace

// The parser reads the same table: a key outside it is refused, one in it accepted.
TEST(SceneDocs, ParserAcceptsExactlyTheTablesKeys) {
  const std::string base = R"({"volume": {"synthetic": "sphere"}, "isovalue": 0, "inside": "below", )";
  EXPECT_NO_THROW(parse_scene(base + R"("outputs": {"plots": false}})", "ok.json"));
  expect_error(base + R"("outputs": {"pictures": false}})", {"outputs.pictures", "unknown field"});
}
