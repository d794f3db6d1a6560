// The margin warning in `isotouch run` (run_scene) on an analytic phantom whose truth is exact:
// a sphere (value = 20 mm - distance from its centre) cut into shells by a transfer function,
// two of them critical (a ring and the core). Timeline carves with their own centres and radii
// cut near them; summary.json's closest approach per critical material must be the one of the
// brush that cut each tick (brute force over that material's voxel centres here, not the
// code's distance field), its entries counted at its own margin.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "isotouch/engine/synthetic.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/run_scene.h"

namespace fs = std::filesystem;
using isotouch::core::Vec3;

namespace {
constexpr int kN = 48;
constexpr double kH = 1e-3;  // spacing [m]

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// VHIP per tick [m] from trace.csv (columns 4-6).
std::vector<Vec3> read_vhips(const fs::path& csv) {
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  std::vector<Vec3> v;
  while (std::getline(in, line)) {
    std::vector<double> c;
    std::istringstream s(line);
    for (std::string tok; std::getline(s, tok, ',') && c.size() < 7;) c.push_back(std::stod(tok));
    if (c.size() < 7) break;
    v.push_back({c[4], c[5], c[6]});
  }
  return v;
}

/// Centres [m] of the voxels whose value lies in [lo, hi) (a transfer function's material).
std::vector<Vec3> voxels_in(const isotouch::engine::Volume& v, double lo, double hi) {
  std::vector<Vec3> out;
  for (int z = 0; z < kN; ++z)
    for (int y = 0; y < kN; ++y)
      for (int x = 0; x < kN; ++x) {
        const double val = v.voxels[v.grid.index(x, y, z)];
        if (val >= lo && val < hi) out.push_back(v.grid.to_world(Vec3{double(x), double(y), double(z)}));
      }
  return out;
}

double nearest(const std::vector<Vec3>& set, const Vec3& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const Vec3& q : set) best = std::min(best, isotouch::core::norm(p - q));
  return best;
}
}  // namespace

// Two timeline carves at fixed points (radius 3 mm 19 mm from the centre, then 3 mm at
// 12 mm), no button: the point probe's VHIP stays on the sphere's surface (20 mm). The
// reported closest approach is that of the carves' surfaces (not the VHIP's with the scene
// brush's radius), within the distance field's slack (a cell diagonal) below the truth.
TEST(MaterialMarginRun, TheBrushCuttingEachTickIsWatched) {
  const auto v = isotouch::engine::make_sphere({kN, kN, kN}, kH, 20);
  const Vec3 c = v.grid.centre_m();
  const Vec3 a = c + Vec3{19e-3, 0, 0}, b = c + Vec3{12e-3, 0, 0};
  std::ostringstream text;
  text.precision(17);
  text << R"({"name": "margin-sphere", "volume": {"synthetic": "sphere", "dims": [48, 48, 48], "spacing_m": 0.001,
              "radius_vox": 20}, "isovalue": 0, "inside": "above",
              "script": {"hold_s": 0.1, "stroke_length_m": 0.0}, "outputs": {"plots": false},
              "materials": {"list": [{"name": "shell", "range": [0, 5]},
                                     {"name": "ring", "range": [5, 6], "critical": true, "margin_mm": 2.5},
                                     {"name": "bone", "range": [6, 12]},
                                     {"name": "core", "range": [12, 100], "critical": true, "margin_mm": 4}]},
              "edits": {"brush": {"kind": "carve", "radius_mm": 0.5, "strength": 100}, "every_ticks": 10,
                        "timeline": [{"t_s": 0.1, "kind": "carve", "radius_mm": 3, "at": [)"
       << a.x * 1e3 << ", " << a.y * 1e3 << ", " << a.z * 1e3 << R"(]},
                                     {"t_s": 0.2, "kind": "carve", "radius_mm": 3, "at": [)"
       << b.x * 1e3 << ", " << b.y * 1e3 << ", " << b.z * 1e3 << R"(]}]}})";
  const auto scene = isotouch::io::parse_scene(text.str(), "margin-sphere.json");
  const fs::path out = temp_dir("isotouch_margin_sphere");
  isotouch::run::RunOptions opt;
  opt.out_dir = out.string();
  opt.progress = false;
  std::ostringstream log;
  isotouch::run::run_scene(scene, opt, log);

  const auto ring = voxels_in(v, 5, 6), core = voxels_in(v, 12, 100);
  ASSERT_FALSE(ring.empty());
  ASSERT_FALSE(core.empty());
  const double diag = std::sqrt(3.0) * kH;
  // The truth: the carves' surfaces and the probe's (0.5 mm) at every VHIP.
  double ring_exact = std::min(nearest(ring, a) - 3e-3, nearest(ring, b) - 3e-3);
  double core_exact = std::min(nearest(core, a) - 3e-3, nearest(core, b) - 3e-3);
  double vhip_only = std::numeric_limits<double>::infinity();
  for (const Vec3& p : read_vhips(out / "trace.csv")) {
    ring_exact = std::min(ring_exact, nearest(ring, p) - 0.5e-3);
    core_exact = std::min(core_exact, nearest(core, p) - 0.5e-3);
    vhip_only = std::min(vhip_only, std::min(nearest(ring, p), nearest(core, p)) - 0.5e-3);
  }
  EXPECT_LT(std::min(ring_exact, core_exact), vhip_only - diag) << "the test's premise: the carves come closer than the probe";
  // Per material: its own closest approach, and entries at its own margin (the ring: both
  // carves, about 1 mm and -0.4 mm from it, the probe between them about 4.5 mm; the core:
  // the second carve only, about 1.3 mm from it, the first about 8.4 mm).
  std::ifstream js(out / "summary.json");
  const auto list = nlohmann::json::parse(js).at("edits").at("critical_margin").at("materials");
  ASSERT_EQ(list.size(), 2u);
  const struct {
    const char* name;
    double margin_mm, exact;
    long entries;
  } want[] = {{"ring", 2.5, ring_exact, 2}, {"core", 4, core_exact, 1}};
  for (std::size_t i = 0; i < 2; ++i) {
    const auto& m = list[i];
    EXPECT_EQ(m.at("name"), want[i].name);
    EXPECT_DOUBLE_EQ(m.at("margin_mm").get<double>(), want[i].margin_mm);
    const double closest = m.at("closest_approach_mm").get<double>() * 1e-3;
    EXPECT_LE(closest, want[i].exact + 1e-9) << want[i].name;
    EXPECT_GE(closest, want[i].exact - diag - 1e-9) << want[i].name;
    EXPECT_EQ(m.at("entries").get<long>(), want[i].entries) << want[i].name;
    EXPECT_GT(m.at("time_inside_s").get<double>(), 0.0) << want[i].name;
    EXPECT_EQ(m.at("voxels_changed").get<long>(), 0) << want[i].name;
  }
  // report.md: a row per critical material.
  std::ifstream md_in(out / "report.md");
  const std::string md((std::istreambuf_iterator<char>(md_in)), std::istreambuf_iterator<char>());
  EXPECT_NE(md.find("| critical margin | ring, margin 2.5 mm: **WARNING** 2 entries"), std::string::npos) << md;
  EXPECT_NE(md.find("| critical margin | core, margin 4 mm: **WARNING** 1 entry,"), std::string::npos) << md;
  fs::remove_all(out);
}

// The run log promises the margin warning only where it runs: with edits (run::EditDriver
// watches them), not in a scene without an "edits" section.
TEST(MaterialMarginRun, TheLogPromisesTheWarningOnlyWithEdits) {
  const std::string base = R"({"name": "margin-log", "volume": {"synthetic": "sphere", "dims": [32, 32, 32],
      "spacing_m": 0.001, "radius_vox": 12}, "isovalue": 0, "inside": "above",
      "script": {"hold_s": 0.05, "stroke_length_m": 0.0}, "outputs": {"plots": false, "trace_csv": false},
      "materials": {"list": [{"name": "core", "range": [6, 100], "critical": true, "margin_mm": 2}]})";
  for (const bool with_edits : {false, true}) {
    const auto scene = isotouch::io::parse_scene(
        base + (with_edits ? R"(, "edits": {"brush": {"kind": "carve", "radius_mm": 1}}})" : "}"), "margin-log.json");
    const fs::path out = temp_dir("isotouch_margin_log");
    isotouch::run::RunOptions opt;
    opt.out_dir = out.string();
    opt.progress = false;
    std::ostringstream log;
    isotouch::run::run_scene(scene, opt, log);
    const std::string text = log.str();
    EXPECT_NE(text.find("(critical)"), std::string::npos) << text;
    EXPECT_EQ(text.find("warning within") != std::string::npos, with_edits) << (with_edits ? "edits" : "no edits") << ":\n" << text;
    fs::remove_all(out);
  }
}
