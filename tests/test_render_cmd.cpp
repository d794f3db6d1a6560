// The render command's parts: the trace reader (what `run` writes comes back, bad cells
// are named), a picture of an analytic sphere (surface pixels against the projected disc),
// and a rotated volume's trace read back into the grid-world frame.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "isotouch/engine/raycast.h"
#include "isotouch/run/picture.h"
#include "isotouch/run/trace_csv.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/io/scene.h"
#include "isotouch/engine/synthetic.h"

namespace fs = std::filesystem;
using namespace isotouch;

namespace {
const std::string kScenes = std::string(ISOTOUCH_TEST_DATA) + "/../scenes";

fs::path temp_dir(const std::string& tag) {
  const fs::path d = fs::temp_directory_path() / ("isotouch_render_cmd_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string error_of(const std::string& path, const engine::Volume& vol) {
  try {
    (void)run::read_trace_csv(path, vol);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(RenderCmd, TraceOfARunReadsBackTickForTick) {
  const fs::path dir = temp_dir("trace");
  io::Scene sc = io::load_scene(kScenes + "/sphere.json");
  sc.draw_plots = false;
  run::RunOptions opt;
  opt.out_dir = dir.string();
  opt.progress = false;
  std::ostringstream log;
  const run::RunMetrics m = run::run_scene(sc, opt, log);
  const engine::Volume vol = run::load_scene_volume(sc);
  const auto rows = run::read_trace_csv((dir / "trace.csv").string(), vol);
  ASSERT_EQ(long(rows.size()), m.ticks);
  long contact = 0;
  double max_f = 0;
  for (const auto& r : rows) {
    contact += r.contact;
    max_f = std::max(max_f, core::norm(r.force_n));
  }
  EXPECT_EQ(contact, m.contact_ticks);
  EXPECT_NEAR(max_f, m.max_force_n, 1e-9 * std::max(1.0, m.max_force_n));  // the CSV's shortest round trip
  fs::remove_all(dir);
}

TEST(RenderCmd, BadTracesNameTheFileLineAndColumn) {
  const fs::path dir = temp_dir("bad");
  const engine::Volume vol = engine::make_sphere({8, 8, 8}, 1e-3, 3);
  const std::string head = "t_s,hip_x_m,hip_y_m,hip_z_m,vhip_x_m,vhip_y_m,vhip_z_m,f_x_n,f_y_n,f_z_n,contact\n";
  const std::string good = "0,0,0,0,0,0,0,0,0,0,0\n";
  struct Case {
    std::string name, text, expect;
  };
  const std::vector<Case> cases = {
      {"header", "time,x\n" + good, "not an isotouch trace.csv"},
      {"cell", head + good + "0.001,0,abc,0,0,0,0,0,0,0,0\n", "line 3, column 3: not a number: 'abc'"},
      {"nan", head + "0,0,0,nan,0,0,0,0,0,0,0\n", "line 2, column 4: not a finite number"},
      {"short", head + "0,0,0,0,0\n", "line 2: 5 columns, at least 11 expected"},
      {"empty", head, "no rows"},
  };
  for (const Case& c : cases) {
    const fs::path p = dir / (c.name + ".csv");
    std::ofstream(p) << c.text;
    const std::string m = error_of(p.string(), vol);
    EXPECT_NE(m.find(p.string()), std::string::npos) << c.name << ": " << m;
    EXPECT_NE(m.find(c.expect), std::string::npos) << c.name << ": " << m;
  }
  EXPECT_NE(error_of((dir / "missing.csv").string(), vol).find("cannot read"), std::string::npos);
  fs::remove_all(dir);
}

TEST(RenderCmd, RotatedVolumeTraceComesBackInGridWorld) {
  // Physical = origin + D (world - origin): a force (0, 0, 1) physical with D permuting the
  // axes is D^T (0, 0, 1) in grid-world.
  const fs::path dir = temp_dir("rot");
  engine::Volume vol = engine::make_sphere({8, 8, 8}, 1e-3, 3);
  vol.direction = {0, 0, 1, 1, 0, 0, 0, 1, 0};
  vol.direction_is_identity = false;
  std::ofstream(dir / "t.csv") << "t_s,hip_x_m,hip_y_m,hip_z_m,vhip_x_m,vhip_y_m,vhip_z_m,f_x_n,f_y_n,f_z_n,contact\n"
                               << "0,0,0,0,0,0,0,0,0,1,1\n";
  const auto rows = run::read_trace_csv((dir / "t.csv").string(), vol);
  ASSERT_EQ(rows.size(), 1u);
  // D^T (0, 0, 1) = the last row of D = (0, 1, 0).
  EXPECT_DOUBLE_EQ(rows[0].force_n.x, 0.0);
  EXPECT_DOUBLE_EQ(rows[0].force_n.y, 1.0);
  EXPECT_DOUBLE_EQ(rows[0].force_n.z, 0.0);
  fs::remove_all(dir);
}

TEST(RenderCmd, SpherePictureCoversTheProjectedDisc) {
  // The CPU reference ray caster on an analytic sphere seen from far: the surface pixels
  // cover pi r'^2 of the image, r' the sphere's projected radius.
  const engine::Volume vol = engine::make_sphere({48, 48, 48}, 1e-3, 15);
  io::Scene sc = io::load_scene(kScenes + "/sphere.json");
  const engine::RaycastField field = run::scene_raycast_field(sc, vol);
  run::PictureRequest req;
  req.width = req.height = 160;
  req.cpu = true;
  const double fov = 20, dist = 0.5;  // m
  const core::Vec3 centre = vol.grid.to_world({23.5, 23.5, 23.5});
  req.view = engine::look_at(centre + core::Vec3{0, -dist, 0}, centre, {0, 0, 1}, fov);
  const engine::RaycastImage img = run::render_picture(nullptr, field, vol.direction, req, "");
  std::size_t hits = 0;
  for (float d : img.depth) hits += d >= 0;
  const double r_m = 15e-3;  // the isosurface radius of make_sphere (tau at the radius)
  const double half_angle = std::asin(r_m / dist);
  const double r_px = std::tan(half_angle) / std::tan(0.5 * fov * M_PI / 180) * 0.5 * req.height;
  const double expect = M_PI * r_px * r_px;
  EXPECT_NEAR(double(hits), expect, 0.03 * expect) << "r' = " << r_px << " px";
}
