// test_overview.cpp - the run's overview picture (run/overview.h): upright from the volume's
// direction matrix, the probe's path where the camera projects it. The picture is read back
// from the PNG file the function wrote; the truth is an analytic shape whose superior part is
// known and a pinhole projection written here.
#include <gtest/gtest.h>
#include <png.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/run/overview.h"
#include "isotouch/run/picture.h"
#include "isotouch/run/render_job.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/run/volume_scene.h"

namespace {
using isotouch::core::Vec3;
namespace engine = isotouch::engine;
namespace run = isotouch::run;
namespace fs = std::filesystem;

struct Rgb {
  int w = 0, h = 0;
  std::vector<unsigned char> px;  // rows top to bottom, 3 bytes a pixel
  const unsigned char* at(int x, int y) const { return &px[3 * (std::size_t(y) * std::size_t(w) + std::size_t(x))]; }
};

Rgb read_png(const std::string& path) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  Rgb out;
  if (!png_image_begin_read_from_file(&img, path.c_str())) return out;
  img.format = PNG_FORMAT_RGB;
  out.w = int(img.width);
  out.h = int(img.height);
  out.px.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.px.data(), 0, nullptr)) out.w = out.h = 0;
  return out;
}

/// A snowman in the physical frame: a ball of radius 14 voxels 6 below the centre and one
/// of 6 voxels 14 above it (physical +z: superior), stored upside down (D = diag(1, -1, -1):
/// index z runs inferior), 2 mm voxels; value = mm inside the nearer ball's surface.
engine::Volume snowman() {
  engine::Volume v;
  const int n = 48;
  const double h = 2e-3;
  v.grid.dims = {n, n, n};
  v.grid.spacing_m = {h, h, h};
  v.direction = {1, 0, 0, 0, -1, 0, 0, 0, -1};
  v.direction_is_identity = false;
  v.path = "synthetic:snowman";
  v.voxels.resize(std::size_t(n) * n * n);
  const Vec3 c = v.to_physical(v.grid.centre_m());
  const Vec3 big = c + Vec3{0, 0, -6 * h}, small = c + Vec3{0, 0, 14 * h};
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Vec3 p = v.index_to_physical({double(x), double(y), double(z)});
        const double d = std::max(14 * h - norm(p - big), 6 * h - norm(p - small));
        v.voxels[v.grid.index(x, y, z)] = float(d * 1e3);
      }
  v.update_stats();
  return v;
}

isotouch::io::Scene iso_zero_scene() {
  isotouch::io::Scene s;
  s.hri.tau = 0;
  s.hri.inside = isotouch::core::InsideIs::kAbove;
  return s;
}

bool magenta(const unsigned char* p) { return p[0] > p[1] + 80 && p[2] > p[1] + 80; }
/// A pixel of the object: neither the background's colour (`bg`, a corner's) nor the path's.
bool surface(const unsigned char* p, const unsigned char* bg) {
  return std::abs(p[0] - bg[0]) + std::abs(p[1] - bg[1]) + std::abs(p[2] - bg[2]) > 30 && !magenta(p);
}

/// The pixel a grid-world point projects to through the pinhole camera `v` (the ray of pixel
/// (px, py) runs along forward * focal + right * (px + 0.5 - W / 2) + up * (H / 2 - py - 0.5)).
std::pair<double, double> project(const engine::CameraView& v, int w, int h, const Vec3& p) {
  const double focal = 0.5 * h / std::tan(0.5 * v.fov_y_deg * M_PI / 180);
  const Vec3 d = p - v.eye;
  const double z = dot(d, v.forward);
  return {focal * dot(d, v.right) / z + 0.5 * w - 0.5, 0.5 * h - 0.5 - focal * dot(d, v.up) / z};
}

}  // namespace

TEST(Overview, SuperiorIsUpAndThePathLiesWhereItProjects) {
  const engine::Volume vol = snowman();
  isotouch::core::SampleField field;
  field.background = -1000;
  // The path: a horizontal line (physical x) across the big ball's front (anterior, -y).
  const Vec3 c = vol.to_physical(vol.grid.centre_m());
  std::vector<isotouch::sim::TraceRow> trace(400);
  for (std::size_t i = 0; i < trace.size(); ++i) {
    const double s = double(i) / double(trace.size() - 1) - 0.5;
    trace[i].t_s = 1e-3 * double(i);
    trace[i].hip_m = vol.to_grid(c + Vec3{0.030 * s, -0.032, -0.012});
    trace[i].vhip_m = trace[i].hip_m;
  }
  const std::string png = (fs::temp_directory_path() / ("test_overview_" + std::to_string(::getpid()) + ".png")).string();
  const int W = 320, H = 320;
  const run::RunPicture pic = run::render_overview(iso_zero_scene(), vol, field, trace, png, nullptr, run::kCpuDevice, W, H);
  ASSERT_EQ(pic.error, "");
  EXPECT_EQ(pic.up, "superior");
  EXPECT_NE(run::overview_sentence(pic).find("superior up"), std::string::npos) << run::overview_sentence(pic);
  const Rgb img = read_png(png);
  fs::remove(png);
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  // Upright: the widest row of the silhouette (the big ball's equator) lies in the lower half
  // of the object's rows; the small ball, superior, is drawn above it.
  int top = H, bottom = -1, widest_row = -1, widest = 0;
  for (int y = 0; y < H; ++y) {
    int width = 0;
    for (int x = 0; x < W; ++x) width += surface(img.at(x, y), img.at(0, 0));
    if (width > 0) top = std::min(top, y), bottom = std::max(bottom, y);
    if (width > widest) widest = width, widest_row = y;
  }
  ASSERT_GT(bottom, top) << "no surface drawn";
  EXPECT_GT(widest_row, (top + bottom) / 2) << "rows " << top << ".." << bottom << ": the widest (big ball) is not below";
  // The path: the pixels at its projected points are magenta; 12 pixels above them are not.
  const engine::CameraView view = run::overview_view(vol, {0.0, isotouch::core::InsideIs::kAbove});
  int on = 0, off = 0, samples = 0;
  for (std::size_t i = 20; i + 20 < trace.size(); i += 10, ++samples) {
    const auto [px, py] = project(view, W, H, trace[i].hip_m);
    const int x = int(std::lround(px)), y = int(std::lround(py));
    ASSERT_TRUE(x >= 0 && x < W && y >= 12 && y < H) << x << ", " << y;
    on += magenta(img.at(x, y));
    off += magenta(img.at(x, y - 12));
  }
  EXPECT_EQ(on, samples) << "path pixels at the projected path";
  EXPECT_EQ(off, 0) << "path pixels 12 px above it";
}

namespace {

/// The object's pixels' centroid in the overview `isotouch run VOLUME` draws for `path` (its
/// scene, its isovalue; no path drawn), as fractions of the width and height from the centre.
std::pair<double, double> object_offset(const std::string& path) {
  const run::VolumeScene vs = run::make_volume_scene(path, std::nullopt);
  const engine::Volume vol = run::load_scene_volume(vs.scene);
  isotouch::core::SampleField field;
  field.background = float(vs.choice.iso.outside_value(vol.min_value, vol.max_value));
  const std::string png =
      (fs::temp_directory_path() / ("test_overview_centre_" + std::to_string(::getpid()) + ".png")).string();
  const int W = 320, H = 320;
  const run::RunPicture pic = run::render_overview(vs.scene, vol, field, {}, png, nullptr, run::kCpuDevice, W, H);
  EXPECT_EQ(pic.error, "");
  EXPECT_EQ(pic.up, "superior");
  const Rgb img = read_png(png);
  fs::remove(png);
  EXPECT_EQ(img.w, W);
  double sx = 0, sy = 0, n = 0;
  for (int y = 0; y < img.h; ++y)
    for (int x = 0; x < img.w; ++x)
      if (surface(img.at(x, y), img.at(0, 0))) sx += x + 0.5, sy += y + 0.5, n += 1;
  EXPECT_GT(n, 0.02 * W * H) << path << ": the object covers " << n << " pixels";
  const std::pair<double, double> off{sx / std::max(n, 1.0) / W - 0.5, sy / std::max(n, 1.0) / H - 0.5};
  std::printf("%s: %.0f object pixels, centroid (%+.3f, %+.3f) of the picture from its centre\n", path.c_str(), n,
              off.first, off.second);
  return off;
}

}  // namespace

// The overview frames the object (the box of its isosurface), not the volume's box: a tooth
// in the lower part of its scan is drawn in the middle. The centroid of a silhouette is not
// its box's projected centre: 5 % of the picture is the tolerance (framing the volume's box,
// the tooth's centroid sat 20.5 % of the height above the centre, the head's 3.9 %).
TEST(Overview, TheObjectIsInTheMiddleOfThePicture) {
  for (const char* file : {"/ct-tooth/tooth.nhdr", "/ct-head-headsq/headsq_64x64x93_int16.mhd"}) {
    const auto [dx, dy] = object_offset(std::string(ISOTOUCH_TEST_DATA) + file);
    EXPECT_LT(std::abs(dx), 0.05) << file << ": centroid " << dx << " of the width right of the centre";
    EXPECT_LT(std::abs(dy), 0.05) << file << ": centroid " << dy << " of the height below the centre";
  }
}

namespace {

/// A ball of radius 8 voxels (value: mm inside its surface, tau = 0) centred at voxel (18, 20, 22)
/// of a 64^3 grid of 1 mm voxels, off the grid's centre; with `strays`, a block of +Inf voxels
/// and a lone voxel above the isovalue in far corners.
engine::Volume ball_off_centre(bool strays) {
  engine::Volume v;
  const int n = 64;
  v.grid.dims = {n, n, n};
  v.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  v.path = "synthetic:ball_off_centre";
  v.voxels.resize(std::size_t(n) * n * n);
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        v.voxels[v.grid.index(x, y, z)] = float(8.0 - std::sqrt((x - 18.0) * (x - 18.0) + (y - 20.0) * (y - 20.0) +
                                                                (z - 22.0) * (z - 22.0)));
  if (strays) {
    for (int z = 56; z < 62; ++z)  // a 6^3 block of +Inf (a tenth of the ball's voxels): no stray
      for (int y = 56; y < 62; ++y)
        for (int x = 56; x < 62; ++x) v.voxels[v.grid.index(x, y, z)] = std::numeric_limits<float>::infinity();
    v.voxels[v.grid.index(62, 3, 60)] = 5.0f;
  }
  v.update_stats();
  return v;
}

/// The object's pixels (neither the corner's colour nor the path's) in `png`: their count and
/// their centroid as fractions of the width and height from the picture's centre.
struct Silhouette {
  double pixels = 0, dx = 0, dy = 0;
};
Silhouette silhouette(const std::string& png) {
  const Rgb img = read_png(png);
  Silhouette s;
  double sx = 0, sy = 0;
  for (int y = 0; y < img.h; ++y)
    for (int x = 0; x < img.w; ++x)
      if (surface(img.at(x, y), img.at(0, 0))) sx += x + 0.5, sy += y + 0.5, s.pixels += 1;
  if (s.pixels > 0) s.dx = sx / s.pixels / img.w - 0.5, s.dy = sy / s.pixels / img.h - 0.5;
  std::printf("%s: %.0f object pixels, centroid (%+.3f, %+.3f) of the picture from its centre\n", png.c_str(), s.pixels,
              s.dx, s.dy);
  return s;
}

}  // namespace

// A block of +Inf voxels and a lone bright voxel far from the object do not stretch the
// overview's frame: the ball stays in the middle and fills the picture (framing the box of
// every voxel above tau, Inf and the stray included, put its centroid (-0.196, +0.189) of the
// picture off the centre, on 2 % of its pixels; counting Inf alone or the stray alone, 21 %).
TEST(Overview, AnInfVoxelAndAStrayVoxelDoNotMoveTheObject) {
  const engine::Volume vol = ball_off_centre(true);
  isotouch::core::SampleField field;
  field.background = -1000;
  const std::string png = (fs::temp_directory_path() / ("test_overview_strays_" + std::to_string(::getpid()) + ".png")).string();
  const run::RunPicture pic = run::render_overview(iso_zero_scene(), vol, field, {}, png, nullptr, run::kCpuDevice, 200, 200);
  ASSERT_EQ(pic.error, "");
  const Silhouette s = silhouette(png);
  fs::remove(png);
  EXPECT_LT(std::abs(s.dx), 0.05) << "centroid " << s.dx << " of the width right of the centre";
  EXPECT_LT(std::abs(s.dy), 0.05) << "centroid " << s.dy << " of the height below the centre";
  // Framed on the ball's box its disc covers 24 % of the picture (the box's bounding sphere
  // fills the height); framed on the scan's box, 2 %.
  EXPECT_GT(s.pixels, 0.15 * 200 * 200);
}

// `isotouch render` frames the object as the overview does (run::frame_object): a ball off the
// centre of its scan is drawn in the middle of the picture, filling it (framing the scan's
// box, its centroid sat (-0.119, +0.100) of the picture off the centre, on 1.6 % of it).
TEST(Overview, IsotouchRenderFramesTheObjectAsTheOverviewDoes) {
  const fs::path dir = fs::temp_directory_path() / ("test_overview_render_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const engine::Volume vol = ball_off_centre(false);
  {
    std::ofstream mha(dir / "ball.mha", std::ios::binary);
    mha << "ObjectType = Image\nNDims = 3\nDimSize = 64 64 64\nElementSpacing = 1 1 1\nOffset = 0 0 0\n"
           "ElementType = MET_FLOAT\nElementByteOrderMSB = False\nElementDataFile = LOCAL\n";
    mha.write(reinterpret_cast<const char*>(vol.voxels.data()), std::streamsize(vol.voxels.size() * sizeof(float)));
    std::ofstream(dir / "ball.json") << R"({"name": "ball", "volume": {"path": "ball.mha"}, "isovalue": 0, "inside": "above"})";
  }
  run::RenderOptions o;
  o.scene = (dir / "ball.json").string();
  o.out = (dir / "ball.png").string();
  o.width = o.height = 200;
  o.cpu = true;
  ASSERT_EQ(run::run_render(o, run::kCpuDevice), 0);
  const Silhouette s = silhouette(o.out);
  fs::remove_all(dir);
  EXPECT_LT(std::abs(s.dx), 0.05) << "centroid " << s.dx << " of the width right of the centre";
  EXPECT_LT(std::abs(s.dy), 0.05) << "centroid " << s.dy << " of the height below the centre";
  EXPECT_GT(s.pixels, 0.15 * 200 * 200);
}
