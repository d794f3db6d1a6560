// Ray caster: GPU against the CPU reference per pixel, an analytic sphere
// against the exact ray-sphere intersection (double precision, computed here), the covered
// pixel count against the sphere's exact projected area, skipping on/off, the clip plane.
// The validation layer (with synchronization validation) is on; any message fails.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <algorithm>
#include <array>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <thread>
#include <tuple>
#include <set>
#include <vector>

#include "isotouch/engine/vk_resources.h"
#include "isotouch/tests/vk_test_context.h"
#include "isotouch/tests/gpu_cpu_compare.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/run/picture.h"
#include "isotouch/io/scene.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"

using namespace isotouch;
using engine::CameraView;
using engine::RaycastField;
using engine::RaycastImage;
using engine::RaycastStyle;
using core::Vec3;

namespace {

const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kHead = kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
constexpr double kPi = 3.14159265358979323846;

engine::VulkanContext& vk() { return test::validated_vk(); }

/// A sphere of radius 60 voxels (1 mm) as a signed distance, positive inside, tau 0.
/// Trilinear interpolation of |x| errs by at most 1/(4 r) = 0.0042 voxel here.
struct SphereCase {
  engine::Volume vol = engine::make_sphere({136, 136, 136}, 1e-3, 60);
  double r_m = 0.060;
  Vec3 centre() const { return vol.grid.centre_m(); }
  RaycastField field() const {
    const core::Isosurface iso{0.0, core::InsideIs::kAbove};
    return engine::make_raycast_field(vol.grid, vol.voxels, iso, float(iso.outside_value(vol.min_value, vol.max_value)));
  }
  /// Eye on the -y axis through the centre at `dist_m`, looking at the centre.
  CameraView view(double dist_m, double fov_deg) const {
    return engine::look_at(centre() + Vec3{0, -dist_m, 0}, centre(), {0, 0, 1}, fov_deg);
  }
};

/// Exact first intersection of a ray with a sphere (double), or -1.
double ray_sphere(const Vec3& o, const Vec3& d, const Vec3& c, double r) {
  const Vec3 oc = o - c;
  const double b = dot(oc, d), q = dot(oc, oc) - r * r, h = b * b - q;
  if (h < 0) return -1;
  return -b - std::sqrt(h);
}

std::size_t hits(const RaycastImage& img) {
  std::size_t n = 0;
  for (float d : img.depth) n += d >= 0;
  return n;
}

int channel(std::uint32_t c, int k) { return int((c >> (8 * k)) & 0xffu); }

/// GPU vs CPU: same hit/miss and depth within a tolerance on all but 0.1 % of the pixels;
/// colour within 3 levels on all but 0.1 %. The depth tolerance: 1e-4 voxel on a CPU device
/// (where every depth must also be bit-identical); on a GPU, whose division and square root
/// are not correctly rounded (Vulkan allows 2.5 ULP and more), the refinement's last bracket
/// at the default step (step / 2^bisections = 0.0078 voxel): a ray a few ULPs off turns a
/// bisection whose midpoint lies within rounding of the surface the other way, and the hit
/// then moves within that bracket, not beyond it.
void expect_gpu_matches_cpu(const RaycastImage& g, const RaycastImage& c, double vox_per_m, const char* what) {
  ASSERT_EQ(g.depth.size(), c.depth.size());
  const double tol_vox = isotouch::test::expects_bit_identity(vk())
                             ? 1e-4
                             : double(RaycastStyle{}.step_vox) / double(1 << ISOTOUCH_RAYCAST_BISECTIONS);
  std::size_t depth_bad = 0, colour_bad = 0, identical = 0;
  double worst = 0;
  for (std::size_t i = 0; i < g.depth.size(); ++i) {
    const bool gh = g.depth[i] >= 0, ch = c.depth[i] >= 0;
    identical += g.depth[i] == c.depth[i];
    if (gh != ch) {
      ++depth_bad;
    } else if (gh) {
      const double e = std::fabs(double(g.depth[i]) - double(c.depth[i])) * vox_per_m;
      worst = std::max(worst, e);
      depth_bad += e > tol_vox;
    }
    for (int k = 0; k < 3; ++k)
      if (std::abs(channel(g.rgba[i], k) - channel(c.rgba[i], k)) > 3) {
        ++colour_bad;
        break;
      }
  }
  // On a CPU device (lavapipe) the shader and the reference do the same float operations:
  // every depth must be bit-identical (the allowance below is for GPUs' own arithmetic).
  if (isotouch::test::expects_bit_identity(vk())) {
    EXPECT_EQ(identical, g.depth.size()) << what << ": depths not bit-identical on a CPU device";
  }
  const std::size_t allow = g.depth.size() / 1000;
  EXPECT_LE(depth_bad, allow) << what << ": pixels whose hit differs GPU vs CPU (worst " << worst << " voxel)";
  EXPECT_LE(colour_bad, allow) << what << ": pixels whose colour differs by more than 3 levels";
  std::printf("%s: %zu of %zu depths bit-identical GPU vs CPU, worst difference %.3g voxel\n", what, identical,
              g.depth.size(), worst);
}

}  // namespace

TEST(Raycast, SphereGpuMatchesCpuPerPixel) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  RaycastStyle st;
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  const RaycastImage g = (*rc.value)->render(view, st, 96, 96);
  const RaycastImage c = engine::render_cpu(f, view, st, 96, 96);
  EXPECT_GT(hits(g), 1000u);
  expect_gpu_matches_cpu(g, c, 1e3, "sphere");
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

// The counting pipelines (the floor of isotouch-sculpt --bench) draw the same picture and count
// what the passes' algorithm reads: per hit pixel the shading (in the march pass) loads the
// 27-voxel block and the normal's 12 face voxels (with quads 12 + 5 texels); the march reads
// at least one cell distance and one trilinear sample (with quads 2 texels, else 8) per hit pixel.
TEST(Raycast, CountedFetchesMatchThePassesWork) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  for (bool quads : {true, false}) {
    auto rc = engine::RayCaster::create(vk(), f, quads);
    ASSERT_TRUE(rc) << rc.error;
    engine::RayCaster& c = **rc.value;
    const RaycastImage plain = c.render(view, RaycastStyle{}, 96, 96);
    EXPECT_EQ(c.last_fetches().march + c.last_fetches().shade, 0u) << "not counting";
    c.set_count_fetches(true);
    const RaycastImage counted = c.render(view, RaycastStyle{}, 96, 96);
    const engine::RayCaster::FetchCount n = c.last_fetches();
    EXPECT_EQ(counted.rgba, plain.rgba) << "quads " << quads << ": counting draws another picture";
    EXPECT_FALSE(counted.reused) << "counting draws the frame whole";
    const std::uint64_t h = hits(counted);
    ASSERT_GT(h, 1000u);
    EXPECT_EQ(n.pixels, 96u * 96u);
    EXPECT_EQ(n.hits, h);
    EXPECT_EQ(n.shade, h * (quads ? 12 + 5 : 27 + 12)) << "quads " << quads;
    EXPECT_GE(n.march, h * (quads ? 1 + 2 : 1 + 8)) << "quads " << quads;
    EXPECT_GE(n.march_lanes, n.march) << "a vector's fetch counts all its lanes";
    EXPECT_GE(n.shade_lanes, n.shade);
    // The march shades its hits: a vector's shading counts all its lanes, at most every
    // marched pixel's (whole workgroups of the frame's pixels); no ray was left to the shade pass.
    EXPECT_LE(n.shade_lanes, (n.pixels + 63) / 64 * 64 * (quads ? 12 + 5 : 27 + 12)) << "at most the frame's vectors";
    EXPECT_EQ(n.listed, 0u) << "no march stopped by the loop budget at this size";
    c.set_count_fetches(false);
    c.render(view, RaycastStyle{}, 96, 97);
    EXPECT_EQ(c.last_fetches().march, 0u) << "counting off again";
    std::printf("quads %d: %zu hits, march %.1f, shade %.1f texel fetches per pixel\n", int(quads), std::size_t(h),
                double(n.march) / double(n.pixels), double(n.shade) / double(n.pixels));
  }
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

TEST(Raycast, HeadCtGpuMatchesCpuPerPixel) {
  const engine::Volume vol = io::load_volume(kHead);
  const core::Isosurface iso{1150, core::InsideIs::kAbove};
  const RaycastField f = engine::make_raycast_field(vol.grid, vol.voxels, iso,
                                                    float(iso.outside_value(vol.min_value, vol.max_value)));
  const CameraView view = engine::orbit_view(f.grid, vol.direction, run::default_camera(vol));
  // The voxels read 4 per texel (quads) and 1 per texel; with and without skipping; with a
  // clip plane through the centre (the cut face: the border of the field's cells too).
  for (bool quads : {true, false}) {
    auto rc = engine::RayCaster::create(vk(), f, quads);
    ASSERT_TRUE(rc) << rc.error;
    EXPECT_EQ((*rc.value)->quads(), quads);
    for (int k = 0; k < 3; ++k) {
      RaycastStyle st;
      st.skip_empty = k != 1;
      if (k == 2) st.clip = engine::ClipPlane{f.grid.centre_m(), -view.forward};
      const RaycastImage g = (*rc.value)->render(view, st, 80, 80);
      const RaycastImage c = engine::render_cpu(f, view, st, 80, 80);
      EXPECT_GT(hits(g), 500u);
      // Anisotropic voxels (3.2 x 3.2 x 1.5 mm): the largest voxels per metre bounds them all.
      const std::string what = std::string("head, ") + (quads ? "quads, " : "1 float, ") +
                               (k == 0 ? "skipping" : k == 1 ? "no skipping" : "clipped");
      expect_gpu_matches_cpu(g, c, 1.0 / 1.5e-3, what.c_str());
    }
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Hit distance against the exact ray-sphere intersection. Rays whose impact parameter is
// at most 0.7 r (incidence under 45 degrees): the trilinear surface lies within 1/(4 r) =
// 0.0042 voxel of the sphere radially, so within 0.006 voxel along those rays; the
// refinement's secant point lies in a bracket of 0.008 voxel (on a field this smooth far
// nearer the root than that). Every such ray must be within 0.01 voxel.
TEST(Raycast, SphereHitDistanceWithinOneHundredthVoxel) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  const int W = 120, H = 100;
  const RaycastImage g = (*rc.value)->render(view, RaycastStyle{}, W, H);
  std::size_t checked = 0;
  double worst = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const Vec3 d = engine::pixel_direction(view, W, H, x, y);
      const Vec3 oc = s.centre() - view.eye;
      const double b = norm(oc - d * dot(oc, d));  // impact parameter [m]
      if (b > 0.7 * s.r_m) continue;
      const double t = ray_sphere(view.eye, d, s.centre(), s.r_m);
      ASSERT_GT(t, 0);
      const float got = g.depth[std::size_t(y) * W + std::size_t(x)];
      ASSERT_GE(got, 0) << "pixel (" << x << ", " << y << ") missed the sphere";
      const double err = std::fabs(double(got) - t) * engine::voxels_per_metre(f.grid, d);
      worst = std::max(worst, err);
      EXPECT_LE(err, 0.01) << "pixel (" << x << ", " << y << ")";
      ++checked;
    }
  EXPECT_GT(checked, 1000u);
  std::printf("sphere: %zu rays, worst hit distance error %.4f voxel\n", checked, worst);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// The sphere seen from distance d with vertical field of view fov projects to a disc of
// radius R = f r / sqrt(d^2 - r^2) pixels (f = (H / 2) / tan(fov / 2); the cone of rays
// tangent to the sphere has half-angle asin(r / d)). Covered pixels within 1 % of pi R^2.
TEST(Raycast, CoveredPixelsMatchProjectedArea) {
  const SphereCase s;
  const RaycastField f = s.field();
  for (double dist : {0.25, 0.4}) {
    const CameraView view = s.view(dist, 40);
    auto rc = engine::RayCaster::create(vk(), f);
    ASSERT_TRUE(rc) << rc.error;
    const int W = 256, H = 256;
    const RaycastImage g = (*rc.value)->render(view, RaycastStyle{}, W, H);
    const double focal = 0.5 * H / std::tan(0.5 * 40 * kPi / 180);
    const double R = focal * s.r_m / std::sqrt(dist * dist - s.r_m * s.r_m);
    const double area = kPi * R * R;
    const double n = double(hits(g));
    EXPECT_NEAR(n, area, 0.01 * area) << "distance " << dist << " m: projected disc radius " << R << " pixels";
    std::printf("sphere at %.2f m: %g pixels covered, projected area %.1f (%.3f %%)\n", dist, n, area,
                100 * (n - area) / area);
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Skipping over bricks whose range cannot hold the isosurface takes the same lattice
// samples: the images must be identical, on the sphere and on a real CT from other angles.
TEST(Raycast, SkippingOnAndOffGiveTheSameImage) {
  const engine::Volume head = io::load_volume(kHead);
  const core::Isosurface iso{1150, core::InsideIs::kAbove};
  const RaycastField hf = engine::make_raycast_field(head.grid, head.voxels, iso,
                                                     float(iso.outside_value(head.min_value, head.max_value)));
  const SphereCase s;
  const RaycastField sf = s.field();
  struct Case {
    const RaycastField* f;
    CameraView view;
  };
  std::vector<Case> cases;
  for (double az : {0.0, 63.0, 200.0}) {
    engine::OrbitCamera cam = run::default_camera(head);
    cam.azimuth_deg = az;
    cam.elevation_deg = az / 5;
    cases.push_back({&hf, engine::orbit_view(hf.grid, head.direction, cam)});
  }
  cases.push_back({&sf, s.view(0.25, 40)});
  for (const Case& c : cases) {
    auto rc = engine::RayCaster::create(vk(), *c.f);
    ASSERT_TRUE(rc) << rc.error;
    RaycastStyle on, off;
    off.skip_empty = false;
    const RaycastImage a = (*rc.value)->render(c.view, on, 128, 128);
    const RaycastImage b = (*rc.value)->render(c.view, off, 128, 128);
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.depth.size(); ++i) differ += a.depth[i] != b.depth[i] || a.rgba[i] != b.rgba[i];
    EXPECT_EQ(differ, 0u) << "pixels that differ with and without skipping";
    EXPECT_GT(hits(a), 500u);
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Thin features against the cell distances: isolated one-voxel blobs (value 1, tau 0.5,
// the rest 0) at pseudo-random places, so many first hits are samples in the cells around a
// blob's voxel (each of the 8 cells sharing it as a corner must be active, and the jumps
// from the cells near it must stop before them); and the same interior with the background
// inside (1) and the near half clipped away (rays start at the cut, not in the entry band),
// so the first hit of a ray missing the blobs is the exit band at the grid's faces (the
// cells there must count the background). Odd sizes; skipping on and off, GPU and CPU
// reference, from oblique angles: the images must be identical (a cell marked inactive or
// a jump too long skips the first inside sample).
TEST(Raycast, ThinFeaturesSkippingOnAndOffGiveTheSameImage) {
  core::Grid grid;
  grid.dims = {45, 40, 43};
  grid.spacing_m = {1e-3, 1e-3, 1e-3};
  std::vector<float> vals(grid.voxel_count(), 0.0f);
  std::uint32_t lcg = 12345u;
  for (float& v : vals) {
    lcg = lcg * 1664525u + 1013904223u;
    v = (lcg >> 24) < 8u ? 1.0f : 0.0f;  // about 3 % of the voxels
  }
  const core::Isosurface iso{0.5, core::InsideIs::kAbove};
  for (float background : {0.0f, 1.0f}) {
    const RaycastField f = engine::make_raycast_field(grid, vals, iso, background);
    auto rc = engine::RayCaster::create(vk(), f);
    ASSERT_TRUE(rc) << rc.error;
    const Vec3 c = grid.centre_m();
    for (const Vec3& dir : {Vec3{0.31, -1, 0.17}, Vec3{-1, 0.23, -0.41}, Vec3{0.2, 0.35, 1}, Vec3{-0.6, -0.7, -0.5}}) {
      const CameraView view = engine::look_at(c + dir * (0.12 / norm(dir)), c, {0.1, 0.2, 1}, 30);
      RaycastStyle on, off;
      if (background > 0.5f) on.clip = engine::ClipPlane{c, dir / norm(dir)};  // rays start inside, not in the band
      off = on;
      off.skip_empty = false;
      const RaycastImage ga = (*rc.value)->render(view, on, 96, 96), gb = (*rc.value)->render(view, off, 96, 96);
      const RaycastImage ca = engine::render_cpu(f, view, on, 96, 96), cb = engine::render_cpu(f, view, off, 96, 96);
      std::size_t differ_gpu = 0, differ_cpu = 0;
      for (std::size_t i = 0; i < ga.depth.size(); ++i) {
        differ_gpu += ga.depth[i] != gb.depth[i] || ga.rgba[i] != gb.rgba[i];
        differ_cpu += ca.depth[i] != cb.depth[i] || ca.rgba[i] != cb.rgba[i];
      }
      EXPECT_EQ(differ_gpu, 0u) << "background " << background << ": GPU pixels that differ with and without skipping";
      EXPECT_EQ(differ_cpu, 0u) << "background " << background << ": CPU pixels that differ with and without skipping";
      EXPECT_GT(hits(gb), 2000u);
      expect_gpu_matches_cpu(ga, ca, 1e3, "thin features, skipping");
    }
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

namespace {

/// Thin-feature volume: one-voxel blobs (1) in zeros, about 3 % of the voxels.
std::vector<float> blobs(const core::Grid& grid, std::uint32_t seed) {
  std::vector<float> vals(grid.voxel_count(), 0.0f);
  for (float& v : vals) {
    seed = seed * 1664525u + 1013904223u;
    v = (seed >> 24) < 8u ? 1.0f : 0.0f;
  }
  return vals;
}

/// Skipping on and off (GPU and CPU reference) must give identical pictures.
void expect_skip_invariant(const RaycastField& f, const CameraView& view, RaycastStyle on, int W, int H,
                           const std::string& what, std::size_t min_hits = 0) {
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  RaycastStyle off = on;
  on.skip_empty = true;
  off.skip_empty = false;
  const RaycastImage ga = (*rc.value)->render(view, on, W, H), gb = (*rc.value)->render(view, off, W, H);
  const RaycastImage ca = engine::render_cpu(f, view, on, W, H), cb = engine::render_cpu(f, view, off, W, H);
  std::size_t differ_gpu = 0, differ_cpu = 0;
  for (std::size_t i = 0; i < ga.depth.size(); ++i) {
    differ_gpu += ga.depth[i] != gb.depth[i] || ga.rgba[i] != gb.rgba[i];
    differ_cpu += ca.depth[i] != cb.depth[i] || ca.rgba[i] != cb.rgba[i];
  }
  EXPECT_EQ(differ_gpu, 0u) << what << ": GPU pixels that differ with and without skipping";
  EXPECT_EQ(differ_cpu, 0u) << what << ": CPU pixels that differ with and without skipping";
  EXPECT_GT(hits(gb), min_hits ? min_hits - 1 : std::size_t(W * H / 20)) << what;
  expect_gpu_matches_cpu(ga, ca, 1e3, what.c_str());
}

/// Brute force: byte per cell c in [-1, n]^3 (stored at c + 1, x fastest) = min(cap,
/// chessboard distance to the nearest cell with a corner v (background outside the grid)
/// that is inside: v > tau above, v < tau below, NaN never).
std::vector<std::uint8_t> brute_cell_distances(const core::Grid& g, const std::vector<float>& v, double tau,
                                               bool above, float bg) {
  const auto& n = g.dims;
  auto value = [&](int x, int y, int z) {
    if (x < 0 || y < 0 || z < 0 || x >= n[0] || y >= n[1] || z >= n[2]) return bg;
    return v[g.index(x, y, z)];
  };
  auto inside = [&](float x) { return above ? double(x) > tau : double(x) < tau; };
  std::vector<std::array<int, 3>> active, all;
  for (int z = -1; z <= n[2]; ++z)
    for (int y = -1; y <= n[1]; ++y)
      for (int x = -1; x <= n[0]; ++x) {
        bool a = false;
        for (int k = 0; k < 8; ++k) a = a || inside(value(x + (k & 1), y + ((k >> 1) & 1), z + (k >> 2)));
        if (a) active.push_back({x, y, z});
        all.push_back({x, y, z});
      }
  std::vector<std::uint8_t> out;
  for (const auto& c : all) {
    int best = int(ISOTOUCH_RAYCAST_DIST_MAX);
    for (const auto& a : active)
      best = std::min(best, std::max({std::abs(c[0] - a[0]), std::abs(c[1] - a[1]), std::abs(c[2] - a[2])}));
    out.push_back(std::uint8_t(best));
  }
  return out;
}

}  // namespace

// The skipping structure against its definition, by brute force: random 0/1 volumes
// (with NaN voxels) of sizes around the 64-bit words of the bit sets, both inside sides,
// the background outside, inside and NaN; a long thin grid whose distances pass the cap.
TEST(Raycast, CellDistancesMatchBruteForce) {
  const std::array<int, 3> sizes[] = {{1, 1, 1}, {7, 5, 9}, {61, 3, 4}, {62, 4, 3}, {63, 2, 3}, {70, 3, 2}};
  std::uint32_t seed = 99u;
  int cases = 0;
  for (const auto& dims : sizes)
    for (bool above : {true, false})
      for (float bg : {0.0f, 1.0f, std::numeric_limits<float>::quiet_NaN()}) {
        core::Grid g;
        g.dims = dims;
        std::vector<float> v(g.voxel_count());
        for (float& x : v) {
          seed = seed * 1664525u + 1013904223u;
          const unsigned r = seed >> 24;
          x = r < 10u ? 1.0f : (r < 14u ? std::numeric_limits<float>::quiet_NaN() : 0.0f);
        }
        const core::Isosurface iso{0.5, above ? core::InsideIs::kAbove : core::InsideIs::kBelow};
        const auto got = engine::cell_distances(g, v, iso, bg);
        const auto want = brute_cell_distances(g, v, 0.5, above, bg);
        ASSERT_EQ(got.size(), want.size());
        std::size_t bad = 0;
        for (std::size_t i = 0; i < got.size(); ++i) bad += got[i] != want[i];
        EXPECT_EQ(bad, 0u) << dims[0] << "x" << dims[1] << "x" << dims[2] << " above " << above << " bg " << bg;
        ++cases;
      }
  // 300 x 1 x 1, one inside voxel at x = 0: cells up to x = 300 are 300 cells away (past the cap).
  core::Grid g;
  g.dims = {300, 1, 1};
  std::vector<float> v(300, 0.0f);
  v[0] = 1.0f;
  const core::Isosurface iso{0.5, core::InsideIs::kAbove};
  EXPECT_EQ(engine::cell_distances(g, v, iso, 0.0f), brute_cell_distances(g, v, 0.5, true, 0.0f));
  EXPECT_EQ(engine::cell_distances(g, v, iso, 0.0f)[301 + 302 * 4], ISOTOUCH_RAYCAST_DIST_MAX);  // x = 300: 300 away
  EXPECT_EQ(cases, 36);
}

// A trilinear value in float can exceed the largest corner: lerp a + t (b - a) rounds
// b - a, and with |a| >> |b| that error (half an ulp of |a|) lands on b. Random pairs
// (a in [-2000, -500], b 8 floats below tau) on a 2x1x1 grid, background a: every
// point (t, 0, 0) whose float trilinear (the shader's lerp order: x, then y, then z) is
// inside must lie in a cell the structure calls active (byte 0).
TEST(Raycast, CellsWithRoundedInsideSamplesAreActive) {
  std::uint32_t seed = 7u;
  auto uni = [&seed]() {
    seed = seed * 1664525u + 1013904223u;
    return float(seed >> 8) / 16777216.0f;  // [0, 1)
  };
  auto lerp1 = [](float a, float b, float t) { return a + t * (b - a); };
  int overshoots = 0, trials = 0;
  for (int i = 0; i < 20000 && overshoots < 20; ++i) {
    const float tau = 1.0f + uni();
    float b = tau;
    for (int u = 0; u < 8; ++u) b = std::nextafter(b, 0.0f);  // 8 ulps below tau
    const float a = -500.0f - 1500.0f * uni();
    for (int j = 0; j < 50; ++j) {
      const float t = 1.0f - 1e-4f * uni();
      // Corners (x, y, z): (0|1, 0, 0) = a, b; every other corner is outside the grid: a.
      const float c00 = lerp1(a, b, t), c10 = lerp1(a, a, t), c01 = lerp1(a, a, t), c11 = lerp1(a, a, t);
      const float v = lerp1(lerp1(c00, c10, 0.0f), lerp1(c01, c11, 0.0f), 0.0f);
      ++trials;
      if (!(v > tau)) continue;
      ++overshoots;
      core::Grid g;
      g.dims = {2, 1, 1};
      const auto d = engine::cell_distances(g, {a, b}, core::Isosurface{tau, core::InsideIs::kAbove}, a);
      EXPECT_EQ(d[1 + 4 * 1 + 4 * 3 * 1], 0u) << "a " << a << " b " << b << " t " << t << " value " << v << " > tau " << tau;
      break;
    }
  }
  std::printf("float trilinear above every corner and above tau: %d cases in %d samples\n", overshoots, trials);
  EXPECT_GT(overshoots, 0) << "no rounding case found: the test does not exercise the margin";
}

// Skipping on and off with rays parallel to grid axes (odd image sizes put a row and a
// column of rays exactly in a coordinate plane: d = 0 on an axis) and from far away (large
// index coordinates: the rounding allowance of the jumps grows with them).
TEST(Raycast, AxisParallelAndFarRaysSkippingOnAndOffGiveTheSameImage) {
  core::Grid grid;
  grid.dims = {37, 41, 29};
  const core::Isosurface iso{0.5, core::InsideIs::kAbove};
  std::vector<float> vals = blobs(grid, 4242u);  // 3 % of the voxels, and as many again:
  std::vector<float> more = blobs(grid, 777u);   // more first hits at every depth
  for (std::size_t i = 0; i < vals.size(); ++i) vals[i] = std::max(vals[i], more[i]);
  const RaycastField f = engine::make_raycast_field(grid, vals, iso, 0.0f);
  const Vec3 c = grid.centre_m();
  for (const Vec3& dir : {Vec3{0, -1, 0}, Vec3{1, 0, 0}, Vec3{0, 0, 1}}) {
    const Vec3 up = std::fabs(dir.z) > 0.5 ? Vec3{0, 1, 0} : Vec3{0, 0, 1};
    expect_skip_invariant(f, engine::look_at(c - dir * 0.1, c, up, 35), RaycastStyle{}, 97, 95, "axis-parallel");
  }
  // 40 m away (about 1000 volume widths), 0.06 degree field of view: the grid fills the image.
  expect_skip_invariant(f, engine::look_at(c + Vec3{0.3, -40, 0.2}, c, {0, 0, 1}, 0.06), RaycastStyle{}, 64, 64,
                        "far eye");
}

// The skipping march's culling: the pixel rectangle and the sample range of the active
// cells' box (much smaller than the volume's box here), with the eye inside the active box,
// between the two boxes, just outside an active-box corner and outside both; with and
// without a clip plane. Skipping on and off, GPU and CPU: the same image.
TEST(Raycast, ActiveBoxCullingKeepsEveryHit) {
  core::Grid grid;
  grid.dims = {60, 50, 40};
  grid.spacing_m = {1e-3, 1e-3, 1e-3};
  std::vector<float> v(grid.voxel_count(), 0.0f);
  std::uint32_t s = 77u;  // blobs only in [20,35]x[15,30]x[12,25]
  for (int z = 12; z <= 25; ++z)
    for (int y = 15; y <= 30; ++y)
      for (int x = 20; x <= 35; ++x) {
        s = s * 1664525u + 1013904223u;
        v[grid.index(x, y, z)] = (s >> 24) < 40u ? 1.0f : 0.0f;
      }
  const RaycastField f = engine::make_raycast_field(grid, v, {0.5, core::InsideIs::kAbove}, 0.0f);
  struct Cam {
    Vec3 eye, target;
    double fov;
    const char* what;
  };
  for (const Cam& c : {Cam{{27.3, 22.1, 18.7}, {60, 40, 30}, 100, "eye inside the active box"},
                       Cam{{5, 5, 5}, {27, 22, 18}, 90, "eye between the boxes"},
                       Cam{{19.5, 14.5, 11.5}, {30, 25, 20}, 120, "eye at an active-box corner"},
                       Cam{{-30, 22, 18}, {27, 22, 18}, 40, "eye outside both"}}) {
    const CameraView view = engine::look_at(grid.to_world(c.eye), grid.to_world(c.target), {0, 0, 1}, c.fov);
    expect_skip_invariant(f, view, RaycastStyle{}, 67, 61, c.what, 1);
    RaycastStyle cl;
    const Vec3 n = Vec3{0.3, -1, 0.2} / norm(Vec3{0.3, -1, 0.2});
    cl.clip = engine::ClipPlane{grid.to_world({27, 22, 18}), n};
    expect_skip_invariant(f, view, cl, 67, 61, std::string(c.what) + ", clipped", 1);
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// No cell can hold an inside point: no march is dispatched with skipping, the shade pass
// gets a 0-workgroup indirect dispatch; the image is background (and the overlay still runs).
TEST(Raycast, VolumeWithNoActiveCellIsAllBackground) {
  core::Grid grid;
  grid.dims = {9, 7, 5};
  grid.spacing_m = {1e-3, 1e-3, 1e-3};
  const RaycastField f = engine::make_raycast_field(grid, std::vector<float>(grid.voxel_count(), 0.0f),
                                                    {0.5, core::InsideIs::kAbove}, 0.0f);
  ASSERT_EQ(std::count(f.cell_dist.begin(), f.cell_dist.end(), std::uint8_t(0)), 0);
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  const CameraView view = engine::look_at(grid.to_world({4, -20, 2}), grid.centre_m(), {0, 0, 1}, 40);
  for (bool skip : {true, false})
    for (bool prims : {false, true}) {
      RaycastStyle st;
      st.skip_empty = skip;
      std::vector<gpu::RaycastPrim> p;
      if (prims) p.push_back(engine::prim_sphere(grid.centre_m(), 2e-3, {1, 0, 0}));
      const RaycastImage g = (*rc.value)->render(view, st, 33, 31, p);
      const RaycastImage c = engine::render_cpu(f, view, st, 33, 31, p);
      EXPECT_EQ(hits(g), 0u);
      EXPECT_EQ(g.depth, c.depth);
      EXPECT_EQ(g.rgba, c.rgba);
      if (prims) {
        EXPECT_NE(std::count(g.rgba.begin(), g.rgba.end(), g.rgba[0]), std::ptrdiff_t(g.rgba.size()));
      }
    }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// llvmpipe's loop budget (65535 trips per invocation, per 8-lane vector): a long ray whose
// every sample lies in an active cell but outside, then a hit far away: the skipping march
// takes one trip per sample (36k here) and must not be cut short. (The review's case: a
// march with an inner and an outer loop per sample runs out of trips and misses the hit.)
TEST(Raycast, LongRayThroughActiveCellsIsNotCutShort) {
  core::Grid grid;
  grid.dims = {2, 2, 400};
  grid.spacing_m = {1e-3, 1e-3, 1e-3};
  std::vector<float> v(grid.voxel_count());
  for (int z = 0; z < 400; ++z)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 2; ++x) v[grid.index(x, y, z)] = z >= 395 ? 1.0f : (x == 0 ? 1.0f : -0.5f);
  const core::Isosurface iso{0.5, core::InsideIs::kAbove};  // the ray at x = 0.5 reads 0.25 until z 394
  const RaycastField f = engine::make_raycast_field(grid, v, iso, 0.0f);
  const CameraView view =
      engine::look_at(grid.to_world({0.5, 0.5, -5}), grid.to_world({0.5, 0.5, 500}), {0, 1, 0}, 10);
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  RaycastStyle st;
  st.step_vox = 0.011f;  // about 36500 samples along z: within ISOTOUCH_RAYCAST_MAX_SAMPLES
  for (bool skip : {true, false}) {
    st.skip_empty = skip;
    const RaycastImage g = (*rc.value)->render(view, st, 1, 1);
    const RaycastImage c = engine::render_cpu(f, view, st, 1, 1);
    ASSERT_GE(c.depth[0], 0.0f);
    // The hit is at z = 394.3 voxel: 399.3 mm from the eye.
    EXPECT_NEAR(c.depth[0], 0.3993, 0.002);
    EXPECT_EQ(g.depth[0], c.depth[0]) << (skip ? "skipping" : "plain");
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// llvmpipe ends an invocation's loops after 65535 iterations: a step that lets a ray take
// more than ISOTOUCH_RAYCAST_MAX_SAMPLES lattice samples is refused, not cut short.
TEST(Raycast, StepThatExceedsTheLoopBudgetIsRefused) {
  RaycastField f;
  f.grid.dims = {1000, 1000, 1000};
  const double diag = std::sqrt(3.0) * 1001;  // the box [-1, n] per axis [voxels]
  const CameraView view = engine::look_at({-1, -1, -1}, {0.5, 0.5, 0.5}, {0, 0, 1}, 30);
  RaycastStyle st;
  st.step_vox = float(diag / ISOTOUCH_RAYCAST_MAX_SAMPLES * 0.9);
  EXPECT_THROW(engine::make_params(f, view, st, 8, 8), std::invalid_argument);
  st.step_vox = float(diag / ISOTOUCH_RAYCAST_MAX_SAMPLES * 1.1);
  EXPECT_NO_THROW(engine::make_params(f, view, st, 8, 8));
  // A step the refinement's 3x3x3 block cannot hold is refused too.
  f.grid.dims = {10, 10, 10};
  st.step_vox = ISOTOUCH_RAYCAST_MAX_STEP;
  EXPECT_NO_THROW(engine::make_params(f, view, st, 8, 8));
  st.step_vox = 1.0f;
  EXPECT_THROW(engine::make_params(f, view, st, 8, 8), std::invalid_argument);
}

// A clip plane through the centre facing the camera removes the near half: what is left
// in view is the cut face, a disc of radius r in the plane, at the plane's distance.
TEST(Raycast, ClipPlaneRemovesTheNearHalf) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  RaycastStyle st;
  st.clip = engine::ClipPlane{s.centre(), -view.forward};
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  const int W = 128, H = 128;
  for (bool skip : {true, false}) {
    st.skip_empty = skip;
    const RaycastImage g = (*rc.value)->render(view, st, W, H);
    const RaycastImage c = engine::render_cpu(f, view, st, W, H);
    std::size_t in_cap = 0, outside = 0;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const Vec3 d = engine::pixel_direction(view, W, H, x, y);
        const double tp = dot(s.centre() - view.eye, view.forward) / dot(d, view.forward);
        const double rho = norm(view.eye + d * tp - s.centre());  // where the ray meets the plane
        const std::size_t i = std::size_t(y) * W + std::size_t(x);
        if (rho < s.r_m - 1e-3) {
          ++in_cap;
          ASSERT_GE(g.depth[i], 0) << "pixel (" << x << ", " << y << ") inside the cut face missed";
          EXPECT_NEAR(double(g.depth[i]), tp, 1e-5) << "pixel (" << x << ", " << y << ") not on the cut face";
        } else if (rho > s.r_m + 1e-3) {
          ++outside;
          EXPECT_LT(g.depth[i], 0) << "pixel (" << x << ", " << y << ") beyond the cut face hit something";
        }
      }
    EXPECT_GT(in_cap, 1000u);
    EXPECT_GT(outside, 1000u);
    expect_gpu_matches_cpu(g, c, 1e3, skip ? "clipped sphere, skipping" : "clipped sphere, no skipping");
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Overlays: a sphere primitive in front of the surface is drawn (its colour), and the
// depth buffer still holds the isosurface (the tests above read it).
TEST(Raycast, ProbePrimitivesAreDrawn) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  sim::TraceRow row;
  row.hip_m = s.centre() + Vec3{0, -s.r_m + 0.002, 0};
  row.vhip_m = s.centre() + Vec3{0, -s.r_m, 0};
  row.force_n = {0, -1.5, 0};
  row.contact = true;
  const auto prims = run::probe_prims(row, 3.0, 1e-3);
  EXPECT_GE(prims.size(), 5u);  // HIP, VHIP, plane, arrow shaft and head
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  const RaycastImage plain = (*rc.value)->render(view, RaycastStyle{}, 64, 64);
  const RaycastImage g = (*rc.value)->render(view, RaycastStyle{}, 64, 64, prims);
  const RaycastImage c = engine::render_cpu(f, view, RaycastStyle{}, 64, 64, prims);
  const std::size_t centre = 32 * 64 + 32;
  EXPECT_NE(g.rgba[centre], plain.rgba[centre]) << "the probe at the image centre is not drawn";
  EXPECT_EQ(g.depth, plain.depth);
  expect_gpu_matches_cpu(g, c, 1e3, "sphere with probe");
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// X-ray and translucent primitives: an opaque x-ray sphere behind the surface (shown
// faintly), one in front of it (drawn opaque), a translucent disc across
// both and a translucent sphere: the overlay pass blends each once, in order, as the CPU
// reference does (its two loops read two lists of the primitives: engine/raycast.cpp).
TEST(Raycast, XrayAndTranslucentPrimitivesMatchCpu) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  const Vec3 front = s.centre() + Vec3{0, -s.r_m, 0};  // the surface point facing the eye
  const std::vector<gpu::RaycastPrim> prims = {
      engine::prim_sphere(front + Vec3{0.004, 0, 0}, 0.006, {0.9f, 0.2f, 0.2f}, 0.5f, true),   // translucent x-ray
      engine::prim_sphere(front + Vec3{-0.008, 0.014, 0}, 0.01, {0.95f, 0.8f, 0.1f}, 1.0f, true), // behind
      engine::prim_disc(front, {0, -1, 0}, 0.012, {0.2f, 0.75f, 0.95f}, 0.4f),
      engine::prim_sphere(front + Vec3{0.006, -0.004, 0.004}, 0.003, {0.15f, 0.8f, 0.25f}, 1.0f, true),
      engine::prim_sphere(front + Vec3{0, -0.002, -0.006}, 0.005, {0.3f, 0.9f, 0.4f}, 0.35f)};
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  const RaycastImage plain = (*rc.value)->render(view, RaycastStyle{}, 96, 96);
  const RaycastImage g = (*rc.value)->render(view, RaycastStyle{}, 96, 96, prims);
  const RaycastImage c = engine::render_cpu(f, view, RaycastStyle{}, 96, 96, prims);
  std::size_t drawn = 0;
  for (std::size_t i = 0; i < g.rgba.size(); ++i) drawn += g.rgba[i] != plain.rgba[i];
  EXPECT_GT(drawn, 200u) << "the primitives are not drawn";
  EXPECT_EQ(g.depth, plain.depth);
  expect_gpu_matches_cpu(g, c, 1e3, "sphere with x-ray and translucent primitives");
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// The overlay drawn in stages (a dispatch per primitive over its own pixels, a pipeline per
// kind) and in one pass (every primitive at every pixel): the same picture, bit for bit, with
// every kind (the probe's sphere, disc, arrow shaft and head), opaque, translucent and x-ray
// primitives overlapping, one partly off the picture; with and without one behind the eye
// (which makes the primitives' rectangle the whole picture); and 40 entries (past the stages'
// 32: one pass either way) against the CPU reference.
TEST(Raycast, OverlayStagesDrawWhatOnePassDraws) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  const Vec3 front = s.centre() + Vec3{0, -s.r_m, 0};
  sim::TraceRow row;
  row.hip_m = front + Vec3{0, 0.002, 0};
  row.vhip_m = front;
  row.force_n = {0.4, -1.5, 0.3};
  row.contact = true;
  std::vector<gpu::RaycastPrim> prims = run::probe_prims(row, 3.0, 1e-3);
  for (const gpu::RaycastPrim& q : {
           engine::prim_sphere(front + Vec3{0.004, 0, 0}, 0.006, {0.9f, 0.2f, 0.2f}, 0.5f, true),
           engine::prim_sphere(front + Vec3{-0.008, 0.014, 0}, 0.01, {0.95f, 0.8f, 0.1f}, 1.0f, true),
           engine::prim_disc(front, {0, -1, 0}, 0.012, {0.2f, 0.75f, 0.95f}, 0.4f),
           engine::prim_sphere(front + Vec3{0.06, 0, 0.003}, 0.02, {0.3f, 0.9f, 0.4f}, 0.35f)})  // partly off the picture
    prims.push_back(q);
  std::set<std::uint32_t> kinds;
  for (const gpu::RaycastPrim& q : prims) kinds.insert(q.kind);
  ASSERT_EQ(kinds.size(), 4u) << "every kind of primitive";
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& r = **rc.value;
  const RaycastImage plain = r.render(view, RaycastStyle{}, 96, 90);
  for (bool behind : {false, true}) {
    std::vector<gpu::RaycastPrim> set = prims;
    if (behind) set.push_back(engine::prim_sphere(s.centre() + Vec3{0, -0.4, 0}, 0.01, {1, 1, 1}));
    ASSERT_LE(2 * set.size(), 32u);  // both lists drawn in stages
    r.set_overlay_stages(true);
    const RaycastImage staged = r.render(view, RaycastStyle{}, 96, 90, set);
    r.set_overlay_stages(false);
    const RaycastImage one_pass = r.render(view, RaycastStyle{}, 96, 90, set);
    EXPECT_GT(staged.overlay_dispatches, 2 + int(prims.size())) << "drawn in stages";
    EXPECT_EQ(one_pass.overlay_dispatches, 1);
    std::size_t drawn = 0, differ = 0, untouched = 0;
    for (std::size_t i = 0; i < staged.rgba.size(); ++i) {
      drawn += staged.rgba[i] != plain.rgba[i];
      differ += staged.rgba[i] != one_pass.rgba[i];
      untouched += staged.rgba[i] == plain.rgba[i];
    }
    EXPECT_GT(drawn, 500u) << "the primitives are not drawn";
    EXPECT_EQ(differ, 0u) << "pixels the stages draw otherwise than the one pass" << (behind ? " (one behind the eye)" : "");
    EXPECT_EQ(staged.depth, one_pass.depth);
    EXPECT_GT(untouched, 1000u) << "the primitives cover the picture: their rectangles are not tested";
  }
  r.set_overlay_stages(true);
  std::vector<gpu::RaycastPrim> many;
  for (int k = 0; k < 40; ++k)
    many.push_back(engine::prim_sphere(front + Vec3{0.002 * (k % 8) - 0.008, -0.003, 0.002 * (k / 8) - 0.004}, 0.0015,
                                       {0.2f, 0.4f + 0.01f * float(k), 0.9f}, k % 3 == 0 ? 0.5f : 1.0f));
  const RaycastImage g = r.render(view, RaycastStyle{}, 96, 90, many);
  EXPECT_EQ(g.overlay_dispatches, 1) << "80 list entries: one pass";
  expect_gpu_matches_cpu(g, engine::render_cpu(f, view, RaycastStyle{}, 96, 90, many), 1e3, "40 primitives");
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(Raycast, PngIsWrittenWholeAndReadable) {
  const std::string path = (std::filesystem::temp_directory_path() / "isotouch_test_raycast.png").string();
  std::vector<std::uint32_t> px(6 * 4, 0xff00ff00u);
  run::write_png(path, 6, 4, px);
  std::ifstream in(path, std::ios::binary);
  char sig[8] = {};
  in.read(sig, 8);
  EXPECT_EQ(std::string(sig, 8), std::string("\x89PNG\r\n\x1a\n", 8));
  std::filesystem::remove(path);
  EXPECT_THROW(run::write_png("/proc/no/such/dir/x.png", 6, 4, px), std::exception);
  EXPECT_THROW(run::write_png(path, 5, 4, px), std::runtime_error);
}

// The picture follows an edit incrementally: RayCaster::update with the bricks a brush
// changed gives, bit for bit, the image and depth of a ray caster created on the edited
// volume (the truth: a full rebuild). Carve and add brushes on the head CT, then undo-like
// restoration of the original values.
namespace {
/// Sets the voxels of the box [lo, hi) of `voxels` (dims `n`, x fastest) to `v` and notes
/// the brick of each (ids as in core/brick_field.h, duplicates allowed) in `dirty`.
void set_box(std::vector<float>& voxels, std::vector<std::uint32_t>& dirty, const std::array<int, 3>& n,
             std::array<int, 3> lo, std::array<int, 3> hi, float v) {
  for (int z = lo[2]; z < hi[2]; ++z)
    for (int y = lo[1]; y < hi[1]; ++y)
      for (int x = lo[0]; x < hi[0]; ++x) {
        voxels[(std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(x)] = v;
        dirty.push_back(std::uint32_t((z / 8 * ((n[1] + 7) / 8) + y / 8) * ((n[0] + 7) / 8) + x / 8));
      }
}
}  // namespace

TEST(Raycast, IncrementalUpdateEqualsFullRebuild) {
  const engine::Volume vol = io::load_volume(kHead);
  const core::Isosurface iso{1150, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  const RaycastField f0 = engine::make_raycast_field(vol.grid, vol.voxels, iso, bg);
  const std::vector<gpu::RaycastPrim> prims = {engine::prim_sphere(vol.grid.centre_m(), 2e-3, {1, 1, 0})};
  // Three views (front, side, back): every edit below shows in one of them.
  std::vector<CameraView> views;
  for (double az : {0.0, 90.0, 180.0}) {
    engine::OrbitCamera cam = run::default_camera(vol);
    cam.azimuth_deg = az;
    views.push_back(engine::orbit_view(f0.grid, vol.direction, cam));
  }
  auto render_all = [&](engine::RayCaster& r) {
    std::vector<RaycastImage> out;
    for (const CameraView& v : views) out.push_back(r.render(v, RaycastStyle{}, 96, 96, prims));
    return out;
  };
  auto rc = engine::RayCaster::create(vk(), f0);
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& inc = **rc.value;
  const auto before = render_all(inc);
  // Edit the values in a box of voxels (as a brush does) and note the bricks it touches.
  std::vector<float> edited = vol.voxels;
  const auto& n = vol.grid.dims;
  std::vector<std::uint32_t> dirty;
  auto edit_box = [&](int x0, int x1, int y0, int y1, int z0, int z1, float v) {
    set_box(edited, dirty, n, {x0, y0, z0}, {x1, y1, z1}, v);
  };
  edit_box(20, 44, 0, 30, 30, 60, -1000.f);  // carve the front of the skull away
  edit_box(28, 36, 50, 64, 70, 93, 2000.f);  // add bone at the back, up to the grid's faces
  edit_box(2, 8, 2, 8, 80, 90, 2000.f);      // and a block in empty space (cells that turn active)
  const engine::RayCaster::UpdateStats st = inc.update(edited, dirty);
  EXPECT_GT(st.bricks, 0u);
  EXPECT_LT(st.value_bytes, vol.voxels.size() * sizeof(float)) << "the whole volume was uploaded";
  EXPECT_GT(st.cell_bytes, 0u);
  const auto after = render_all(inc);
  auto full = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, edited, iso, bg));
  ASSERT_TRUE(full) << full.error;
  const auto truth = render_all(**full.value);
  for (std::size_t v = 0; v < views.size(); ++v) {
    EXPECT_NE(after[v].rgba, before[v].rgba) << "view " << v << ": the edit is not visible";
    EXPECT_EQ(after[v].rgba, truth[v].rgba) << "view " << v;
    EXPECT_EQ(after[v].depth, truth[v].depth) << "view " << v;
  }
  EXPECT_EQ(inc.field().cell_dist, (*full.value)->field().cell_dist);
  // The voxels read 1 per texel (no quads): the same pictures, so the quads updated above
  // hold the edited voxels.
  auto plain = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, edited, iso, bg), false);
  ASSERT_TRUE(plain) << plain.error;
  EXPECT_TRUE(inc.quads()) << "the head's caster does not read quads: the test above says nothing about them";
  EXPECT_FALSE((*plain.value)->quads());
  const auto one_float = render_all(**plain.value);
  for (std::size_t v = 0; v < views.size(); ++v) {
    EXPECT_EQ(after[v].rgba, one_float[v].rgba) << "view " << v << ": quads and 1 float per texel differ";
    EXPECT_EQ(after[v].depth, one_float[v].depth) << "view " << v;
  }
  // Back to the original values (an undo): the first picture again, bit for bit.
  inc.update(vol.voxels, dirty);
  const auto undone = render_all(inc);
  for (std::size_t v = 0; v < views.size(); ++v) {
    EXPECT_EQ(undone[v].rgba, before[v].rgba) << "view " << v;
    EXPECT_EQ(undone[v].depth, before[v].depth) << "view " << v;
  }
  EXPECT_THROW(inc.update(vol.voxels, {std::uint32_t(1) << 30}), std::invalid_argument);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// A volume larger than one storage binding (maxStorageBufferRange, 128 MiB on lavapipe): a
// 512^3 float sphere (512 MiB) renders through the texel bindings as the CPU reference
// draws it, and an edit on its far corner brick (the last texels) shows.
TEST(Raycast, VolumeLargerThanOneStorageBindingRenders) {
  engine::Volume vol = engine::make_sphere({512, 512, 512}, 0.5e-3, 200);
  if (vol.voxels.size() * sizeof(float) <= vk().max_binding_bytes())  // lavapipe: 128 MiB; an NVIDIA GPU: 4 GiB
    GTEST_SKIP() << "this device's storage bindings hold the 512^3 volume (" << vk().max_binding_bytes() << " bytes)";
  const core::Isosurface iso{0.0, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  const core::Grid grid = vol.grid;
  const RaycastField f = engine::make_raycast_field(grid, std::move(vol.voxels), iso, bg);
  if (f.values.size() > vk().properties().limits.maxTexelBufferElements)
    GTEST_SKIP() << "this device's maxTexelBufferElements is below 512^3";
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  EXPECT_FALSE((*rc.value)->quads()) << "514^3 quads (2.2 GB) are beyond the budget and the texel limit";
  const Vec3 c = grid.centre_m();
  const CameraView view = engine::look_at(c + Vec3{0.18, -0.3, 0.24}, c, {0, 0, 1}, 40);
  const RaycastImage g = (*rc.value)->render(view, RaycastStyle{}, 64, 64);
  expect_gpu_matches_cpu(g, engine::render_cpu(f, view, RaycastStyle{}, 64, 64), 1e3, "512^3 sphere");
  EXPECT_GT(hits(g), 500u);
  // Fill the far corner (x, z = 480..511, y = 0..31: toward the eye; 4^3 bricks, the last
  // voxels) with material.
  std::vector<float> edited = f.values;
  std::vector<std::uint32_t> bricks;
  for (int z = 480; z < 512; ++z)
    for (int y = 0; y < 32; ++y)
      for (int x = 480; x < 512; ++x) {
        edited[(std::size_t(z) * 512 + std::size_t(y)) * 512 + std::size_t(x)] = 100.f;
        bricks.push_back(std::uint32_t((z / 8 * 64 + y / 8) * 64 + x / 8));
      }
  (*rc.value)->update(edited, bricks);
  const RaycastImage e = (*rc.value)->render(view, RaycastStyle{}, 64, 64);
  std::size_t nearer = 0;  // the block lies in front of the sphere as seen from the eye
  for (std::size_t i = 0; i < e.depth.size(); ++i) nearer += e.depth[i] >= 0 && (g.depth[i] < 0 || e.depth[i] < g.depth[i] - 0.01f);
  EXPECT_GT(nearer, 10u) << "the block added at the far corner does not show";
  expect_gpu_matches_cpu(e, engine::render_cpu((*rc.value)->field(), view, RaycastStyle{}, 64, 64), 1e3, "512^3 edited");
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// A volume past one texel binding of single floats (a 512 x 512 x 600 CT on lavapipe: 1.6e8
// voxels against 2^27 texels) is read 4 voxels per texel. Forced here on the head CT by a
// binding limit of 200,000 texels (380,928 voxels, 103,455 cell texels): every picture, with
// skipping and tile starts, without, clipped, and after an edit at the volume's last
// slices, equals bit for bit the one-float-per-texel caster's. A limit the voxels exceed even
// 4 per texel is refused with the volume's size and the limit.
TEST(Raycast, FourVoxelsPerTexelPastOneBindingDrawTheSamePicture) {
  const engine::Volume vol = io::load_volume(kHead);
  const core::Isosurface iso{1150, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  const RaycastField f = engine::make_raycast_field(vol.grid, vol.voxels, iso, bg);
  constexpr std::uint64_t kLimit = 200000;
  ASSERT_GT(f.values.size(), kLimit);
  auto four = engine::RayCaster::create(vk(), f, true, kLimit);
  ASSERT_TRUE(four) << four.error;
  auto one = engine::RayCaster::create(vk(), f, false);
  ASSERT_TRUE(one) << one.error;
  EXPECT_TRUE((*four.value)->four_voxels_per_texel());
  EXPECT_FALSE((*four.value)->quads()) << "the cells exceed the forced limit: no quads";
  EXPECT_FALSE((*one.value)->four_voxels_per_texel());
  RaycastStyle plain, clipped;
  plain.skip_empty = false;
  clipped.clip = engine::ClipPlane{vol.grid.centre_m(), {0, -1, 0}};
  std::vector<CameraView> views;
  for (double az : {0.0, 90.0, 200.0}) {
    engine::OrbitCamera cam = run::default_camera(vol);
    cam.azimuth_deg = az;
    views.push_back(engine::orbit_view(f.grid, vol.direction, cam));
  }
  auto expect_same = [&](const char* what) {
    std::size_t hit = 0;
    for (const RaycastStyle& st : {RaycastStyle{}, plain, clipped})
      for (std::size_t v = 0; v < views.size(); ++v) {
        const RaycastImage a = (*four.value)->render(views[v], st, 96, 96), b = (*one.value)->render(views[v], st, 96, 96);
        EXPECT_EQ(a.rgba, b.rgba) << what << ", view " << v << ": 4 voxels per texel draw another picture";
        EXPECT_EQ(a.depth, b.depth) << what << ", view " << v;
        hit += hits(b);
      }
    EXPECT_GT(hit, 5000u) << what << ": the pictures show little of the head";
  };
  expect_same("as loaded");
  // Bone added on the last slices (the last texels) and a carve in front: both casters
  // draw the same again.
  std::vector<float> edited = vol.voxels;
  std::vector<std::uint32_t> dirty;
  set_box(edited, dirty, vol.grid.dims, {10, 10, 84}, {54, 54, 93}, 2000.f);
  set_box(edited, dirty, vol.grid.dims, {20, 0, 30}, {44, 30, 60}, -1000.f);
  (*four.value)->update(edited, dirty);
  (*one.value)->update(edited, dirty);
  expect_same("edited");
  auto refused = engine::RayCaster::create(vk(), f, true, 50000);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error.find("64 x 64 x 93 (380928 voxels"), std::string::npos) << refused.error;
  EXPECT_NE(refused.error.find("50000 texels"), std::string::npos) << refused.error;
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Frames with the last frame's camera draw again only where the probe or an edit can show
// (RaycastImage::reused), and each equals, bit for bit, a full frame of a new ray caster on
// the same values (the truth): the probe moved, the probe gone, an edit (carve in front of
// the camera, bone added behind the skull), the edit undone, and the frames that cannot
// reuse (no linear colour kept, another style).
TEST(Raycast, ReusedFramesEqualFullFrames) {
  const engine::Volume vol = io::load_volume(kHead);
  const core::Isosurface iso{1150, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  const CameraView view = engine::orbit_view(vol.grid, vol.direction, run::default_camera(vol));
  const Vec3 c = vol.grid.centre_m();
  const std::vector<gpu::RaycastPrim> at_a = {engine::prim_sphere(c + Vec3{0, -0.06, 0.01}, 4e-3, {1, 1, 0})};
  const std::vector<gpu::RaycastPrim> at_b = {engine::prim_sphere(c + Vec3{0.02, -0.06, -0.01}, 4e-3, {0, 1, 0}),
                                              engine::prim_capsule(c, c + Vec3{0, -0.08, 0}, 1e-3, {1, 0, 0})};
  RaycastStyle clipped;
  clipped.clip = engine::ClipPlane{c, {0, -1, 0}};
  auto truth = [&](const std::vector<float>& values, const RaycastStyle& st, const std::vector<gpu::RaycastPrim>& prims) {
    auto fresh = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, values, iso, bg));
    EXPECT_TRUE(fresh) << fresh.error;
    return (*fresh.value)->render(view, st, 320, 240, prims);
  };
  auto expect_same = [](const RaycastImage& got, const RaycastImage& want, bool reused, const char* what) {
    EXPECT_EQ(got.reused, reused) << what;
    EXPECT_TRUE(got.rgba == want.rgba) << what << ": colours differ from a full frame";
    EXPECT_TRUE(got.depth == want.depth) << what << ": depths differ from a full frame";
  };
  auto rc = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, vol.voxels, iso, bg));
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& r = **rc.value;
  expect_same(r.render(view, RaycastStyle{}, 320, 240), truth(vol.voxels, RaycastStyle{}, {}), false, "first frame");
  expect_same(r.render(view, RaycastStyle{}, 320, 240, at_a), truth(vol.voxels, RaycastStyle{}, at_a), false,
              "a probe on a frame without linear colour");
  expect_same(r.render(view, RaycastStyle{}, 320, 240, at_b), truth(vol.voxels, RaycastStyle{}, at_b), true, "probe moved");
  expect_same(r.render(view, RaycastStyle{}, 320, 240), truth(vol.voxels, RaycastStyle{}, {}), true, "probe gone");
  // Edits: carve into the front of the skull, add bone at the back (hidden) and in empty space.
  std::vector<float> edited = vol.voxels;
  const auto& n = vol.grid.dims;
  std::vector<std::uint32_t> dirty;
  auto edit_box = [&](int x0, int x1, int y0, int y1, int z0, int z1, float v) {
    set_box(edited, dirty, n, {x0, y0, z0}, {x1, y1, z1}, v);
  };
  edit_box(26, 34, 0, 14, 40, 48, -1000.f);
  edit_box(28, 36, 50, 64, 70, 93, 2000.f);
  edit_box(2, 8, 2, 8, 80, 90, 2000.f);
  r.update(edited, dirty);
  const RaycastImage carved = r.render(view, RaycastStyle{}, 320, 240, at_a);
  expect_same(carved, truth(edited, RaycastStyle{}, at_a), true, "after the edits");
  expect_same(r.render(view, clipped, 320, 240, at_a), truth(edited, clipped, at_a), false, "another style");
  r.update(vol.voxels, dirty);
  expect_same(r.render(view, clipped, 320, 240, at_b), truth(vol.voxels, clipped, at_b), true, "the edits undone, clipped");
  EXPECT_NE(carved.rgba, truth(vol.voxels, RaycastStyle{}, at_a).rgba) << "the carve is not visible";
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Progressive refinement of a still view (RayCaster::render_rows): bands of rows drawn one
// per frame after a frame of another view at the same size (its rows must not survive) or at
// a lower resolution (the buffers resized), in order, uneven: each band's rows are the
// truth's (a full frame of a new ray caster) bit for bit as soon as it is drawn, and the
// frame after the last band reuses the picture they leave, the truth bit for bit.
TEST(Raycast, RowBandsOfAStillViewEndEqualToTheFullFrame) {
  const engine::Volume vol = io::load_volume(kHead);
  const core::Isosurface iso{1150, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  engine::OrbitCamera cam = run::default_camera(vol);
  const CameraView view = engine::orbit_view(vol.grid, vol.direction, cam);
  cam.azimuth_deg += 40;
  const CameraView other = engine::orbit_view(vol.grid, vol.direction, cam);
  const int W = 320, H = 240;
  const RaycastImage truth = [&] {
    auto fresh = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, vol.voxels, iso, bg));
    EXPECT_TRUE(fresh) << fresh.error;
    return (*fresh.value)->render(view, RaycastStyle{}, W, H);
  }();
  auto rc = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, vol.voxels, iso, bg));
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& r = **rc.value;
  // The truth's rows [y0, y0 + got.height) are `got`'s pixels.
  const auto rows_equal = [&](const RaycastImage& got, int y0) {
    const auto at = std::ptrdiff_t(y0) * W, n = std::ptrdiff_t(got.height) * W;
    return got.width == W && std::ptrdiff_t(got.rgba.size()) == n && std::ptrdiff_t(got.depth.size()) == n &&
           std::equal(got.rgba.begin(), got.rgba.end(), truth.rgba.begin() + at) &&
           std::equal(got.depth.begin(), got.depth.end(), truth.depth.begin() + at);
  };
  for (const auto& [before_w, before_h, what] : {std::tuple{W, H, "after another view"}, std::tuple{W / 2, H / 2, "after a half-size frame"}}) {
    const RaycastImage moving = r.render(other, RaycastStyle{}, before_w, before_h);
    if (before_w == W) ASSERT_FALSE(rows_equal(moving, 0)) << "the other view is the truth (the test's premise)";
    const int bands[][2] = {{0, 37}, {37, 100}, {100, 101}, {101, 200}, {200, H}};
    for (const auto& b : bands) {
      const RaycastImage band = r.render_rows(view, RaycastStyle{}, W, H, b[0], b[1]);
      EXPECT_FALSE(band.reused) << what;
      EXPECT_EQ(band.height, b[1] - b[0]) << what;
      EXPECT_TRUE(rows_equal(band, b[0])) << what << ": rows [" << b[0] << ", " << b[1] << ") differ from the full frame's";
    }
    // The buffers after the bands: a frame that reuses them draws nothing again (no edit, no
    // overlay) and reads them back whole.
    const RaycastImage next = r.render(view, RaycastStyle{}, W, H);
    EXPECT_TRUE(next.reused) << what << ": the refined picture is not reused";
    EXPECT_TRUE(next.rgba == truth.rgba && next.depth == truth.depth) << what;
  }
  // With the probe's glyph (the window's case): the render after the bands draws it over the
  // bands' picture (from their linear colour) and reuses the rest.
  const Vec3 centre = vol.grid.to_world({vol.grid.dims[0] / 2.0, vol.grid.dims[1] / 2.0, vol.grid.dims[2] / 2.0});
  const std::vector<gpu::RaycastPrim> glyph = {engine::prim_sphere(centre, 0.02, {0.9f, 0.2f, 0.2f})};
  const RaycastImage truth_glyph = [&] {
    auto fresh = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, vol.voxels, iso, bg));
    EXPECT_TRUE(fresh) << fresh.error;
    return (*fresh.value)->render(view, RaycastStyle{}, W, H, glyph);
  }();
  ASSERT_NE(truth_glyph.rgba, truth.rgba) << "the glyph is drawn (the test's premise)";
  r.render(other, RaycastStyle{}, W / 2, H / 2, glyph);
  for (int y = 0; y < H; y += 60) r.render_rows(view, RaycastStyle{}, W, H, y, std::min(H, y + 60));
  const RaycastImage with_glyph = r.render(view, RaycastStyle{}, W, H, glyph);
  EXPECT_TRUE(with_glyph.reused) << "the bands' picture is not reused under a glyph";
  EXPECT_TRUE(with_glyph.rgba == truth_glyph.rgba && with_glyph.depth == truth_glyph.depth);
  EXPECT_THROW(r.render_rows(view, RaycastStyle{}, W, H, 10, 10), std::invalid_argument);
  EXPECT_THROW(r.render_rows(view, RaycastStyle{}, W, H, 0, H + 1), std::invalid_argument);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// The same on a volume larger than the reach of the cell distances' local recompute (a
// sphere of 200^3 voxels): edits one at a time, each far from the others, each update must
// leave exactly the cell distances of a full rebuild and recompute only around the edit;
// one edit that raises the largest |value| recomputes every cell.
TEST(Raycast, IncrementalUpdateRecomputesCellDistancesLocally) {
  const engine::Volume vol = engine::make_sphere({200, 200, 200}, 1e-3, 60);
  const core::Isosurface iso{0.0, core::InsideIs::kAbove};
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  auto rc = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, vol.voxels, iso, bg));
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& inc = **rc.value;
  std::vector<float> v = vol.voxels;
  const auto& n = vol.grid.dims;
  const int nbx = (n[0] + 7) / 8, nby = (n[1] + 7) / 8;
  const std::size_t cells = std::size_t(n[0] + 2) * (n[1] + 2) * (n[2] + 2);
  auto edit = [&](int x0, int y0, int z0, int size, float value) {
    std::vector<std::uint32_t> dirty;
    for (int z = z0; z < z0 + size; ++z)
      for (int y = y0; y < y0 + size; ++y)
        for (int x = x0; x < x0 + size; ++x) {
          v[(std::size_t(z) * n[1] + y) * n[0] + x] = value;
          dirty.push_back(std::uint32_t((z / 8 * nby + y / 8) * nbx + x / 8));
        }
    return inc.update(v, dirty);
  };
  const float inside = vol.max_value * 0.5f, outside = vol.min_value * 0.5f;
  struct Case { int x, y, z, size; float value; bool local; };
  for (const Case& c : {Case{96, 96, 36, 8, outside, true},     // carve into the sphere's bottom
                        Case{4, 4, 4, 5, inside, true},         // a block in empty space, at a corner
                        Case{180, 20, 100, 6, inside, true},    // another, near a face
                        Case{96, 160, 96, 4, outside, true},    // carve near the sphere's side
                        Case{100, 100, 180, 3, vol.max_value * 4, false}}) {  // a new largest |value|
    const engine::RayCaster::UpdateStats st = edit(c.x, c.y, c.z, c.size, c.value);
    const RaycastField truth = engine::make_raycast_field(vol.grid, v, iso, bg);
    EXPECT_EQ(inc.field().cell_dist, truth.cell_dist) << "edit at " << c.x << " " << c.y << " " << c.z;
    if (c.local)
      EXPECT_LT(st.cells_recomputed, cells / 4) << "edit at " << c.x << " " << c.y << " " << c.z;
    else
      EXPECT_EQ(st.cells_recomputed, cells);
  }
  const CameraView view = engine::look_at(vol.grid.centre_m() + Vec3{0.05, -0.3, 0.08}, vol.grid.centre_m(), {0, 0, 1}, 40);
  auto full = engine::RayCaster::create(vk(), engine::make_raycast_field(vol.grid, v, iso, bg));
  ASSERT_TRUE(full) << full.error;
  const RaycastImage a = inc.render(view, RaycastStyle{}, 96, 96), b = (*full.value)->render(view, RaycastStyle{}, 96, 96);
  EXPECT_EQ(a.rgba, b.rgba);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Tile starts (shaders/raycast_tiles.comp): a cone march per tile of 8 x 8 pixels decides
// which tiles are marched at all and where each of their rays' marches starts. A tile left
// out that holds a hit, or a start past a pixel's first inside sample, changes that pixel.
// Against the march without tile starts and the CPU reference, bit for bit: one-voxel
// blobs (a first hit can be a single voxel anywhere in a tile's cone) in a grid of unequal
// spacings (the cone's width in cells differs per axis); from far (cones many voxels wide;
// the grid covers part of the image, so tiles along its outline are partly empty) to near,
// and from inside the grid (the cone starts at t = 0 among active cells); with and without
// a clip plane; image sizes that are not whole tiles.
TEST(Raycast, TileStartsKeepEveryFirstHit) {
  core::Grid grid;
  grid.dims = {37, 41, 29};
  grid.spacing_m = {1.0e-3, 1.3e-3, 0.8e-3};
  const core::Isosurface iso{0.5, core::InsideIs::kAbove};
  std::vector<float> vals = blobs(grid, 4242u);  // 3 % of the voxels, and as many again:
  std::vector<float> more = blobs(grid, 777u);   // more first hits at every depth
  for (std::size_t i = 0; i < vals.size(); ++i) vals[i] = std::max(vals[i], more[i]);
  // Boxes of ones: flat faces, so a ray's first inside sample can lie half a voxel into the
  // first active cell (a start past an active cell's edge misses it).
  core::Grid box_grid = grid;
  box_grid.dims = {53, 47, 41};
  std::vector<float> boxes(box_grid.voxel_count(), 0.0f);
  std::uint32_t lcg = 99u;
  auto next = [&lcg](int n) {
    lcg = lcg * 1664525u + 1013904223u;
    return int((lcg >> 8) % std::uint32_t(n));
  };
  for (int b = 0; b < 14; ++b) {
    const int x0 = next(45), y0 = next(39), z0 = next(33), sx = 2 + next(8), sy = 2 + next(8), sz = 2 + next(8);
    for (int z = z0; z < std::min(41, z0 + sz); ++z)
      for (int y = y0; y < std::min(47, y0 + sy); ++y)
        for (int x = x0; x < std::min(53, x0 + sx); ++x) boxes[box_grid.index(x, y, z)] = 1.0f;
  }
  const RaycastField fields[2] = {engine::make_raycast_field(grid, vals, iso, 0.0f),
                                  engine::make_raycast_field(box_grid, boxes, iso, 0.0f)};
  for (const RaycastField& f : fields) {
    auto rc = engine::RayCaster::create(vk(), f);
    ASSERT_TRUE(rc) << rc.error;
    const Vec3 c = f.grid.centre_m();
    struct View {
      Vec3 dir;
      double dist_m;
      int w, h;
      bool clip;
      std::size_t min_hits;
    };
    const View views[] = {
        {{0.31, -1, 0.17}, 0.20, 101, 77, false, 100},     // far: the grid in a few tiles
        {{-1, 0.23, -0.41}, 0.09, 93, 70, false, 600},
        {{0.2, 0.35, 1}, 0.06, 64, 48, true, 350},         // the near half cut away
        {{-0.6, -0.7, -0.5}, 0.004, 83, 61, false, 1400},   // the eye inside the grid
        {{0.5, 0.1, -1}, 0.03, 120, 90, false, 3400},       // close: the blobs many pixels wide
    };
    for (const View& v : views) {
      const Vec3 u = v.dir / norm(v.dir);
      const CameraView view = engine::look_at(c + u * v.dist_m, c, {0.1, 0.2, 1}, 40);
      RaycastStyle on;
      if (v.clip) on.clip = engine::ClipPlane{c, u};
      RaycastStyle off = on;
      off.tile_starts = false;
      const RaycastImage a = (*rc.value)->render(view, on, v.w, v.h);
      const RaycastImage b = (*rc.value)->render(view, off, v.w, v.h);
      const RaycastImage cpu = engine::render_cpu(f, view, on, v.w, v.h);
      // The tile pass's own claim, without the march's margin of two samples: the tile's
      // rays meet no active cell before its start. In these volumes every surface point lies
      // at least half a voxel inside the active cells (a one-voxel blob is inside only within
      // half a voxel of its centre per axis, a box face half a voxel inside its first active
      // cell), so no hit may lie before its tile's start (0.05 voxel for rounding).
      (*rc.value)->render(view, on, v.w, v.h);  // the tile starts of that frame (b had none)
      const std::vector<float> starts = (*rc.value)->last_tile_starts();
      const std::vector<float> block_starts = (*rc.value)->last_block_starts();
      const int T = int(ISOTOUCH_RAYCAST_TILE), tiles_x = (v.w + T - 1) / T;
      const int B = int(ISOTOUCH_RAYCAST_BLOCK), blocks_x = (v.w + B - 1) / B;
      ASSERT_EQ(starts.size(), std::size_t(tiles_x) * std::size_t((v.h + T - 1) / T));
      ASSERT_EQ(block_starts.size(), std::size_t(blocks_x) * std::size_t((v.h + B - 1) / B));
      std::size_t late = 0, late_block = 0, culled = 0, before_tile = 0;
      double ahead_vox = 0, block_ahead_vox = 0;  // how far before the hits the starts are, in voxels (mean)
      for (int py = 0; py < v.h; ++py)
        for (int px = 0; px < v.w; ++px) {
          const float depth = cpu.depth[std::size_t(py) * std::size_t(v.w) + std::size_t(px)];
          const float start = starts[std::size_t(py / T) * std::size_t(tiles_x) + std::size_t(px / T)];
          const float block = block_starts[std::size_t(py / B) * std::size_t(blocks_x) + std::size_t(px / B)];
          culled += !(start < std::numeric_limits<float>::infinity());
          before_tile += block < start;  // a block's rays are some of its tile's: never earlier
          if (depth < 0) continue;
          const double vpm = engine::voxels_per_metre(f.grid, engine::pixel_direction(view, v.w, v.h, px, py));
          late += double(start) > double(depth) + 0.05 / vpm;
          late_block += double(block) > double(depth) + 0.05 / vpm;
          ahead_vox += (double(depth) - double(start)) * vpm;
          block_ahead_vox += (double(depth) - double(block)) * vpm;
        }
      const double n_hits = double(std::max<std::size_t>(hits(cpu), 1));
      std::printf("%zu of %d pixels in tiles left out; tile starts %.2f, block starts %.2f voxels before the hits (mean)\n",
                  culled, v.w * v.h, ahead_vox / n_hits, block_ahead_vox / n_hits);
      EXPECT_EQ(late, 0u) << "hit pixels whose tile starts past the hit";
      EXPECT_EQ(late_block, 0u) << "hit pixels whose block starts past the hit";
      EXPECT_EQ(before_tile, 0u) << "pixels whose block starts before its tile";
      // The block pass does its job: nearer the hits than the tiles' starts on the whole
      // (with the eye outside the grid; from inside both start at the eye among active cells).
      if (v.dist_m > 0.01) {
        EXPECT_LT(block_ahead_vox, ahead_vox) << "block starts no nearer than the tiles'";
      }
      std::size_t differ = 0;
      for (std::size_t i = 0; i < a.depth.size(); ++i) differ += a.depth[i] != b.depth[i] || a.rgba[i] != b.rgba[i];
      const std::string what = std::string(&f == fields ? "blobs" : "boxes") + ", tile starts, eye " +
                               std::to_string(v.dist_m) + " m from the centre";
      EXPECT_EQ(differ, 0u) << what << ": pixels that differ with and without tile starts";
      EXPECT_GE(hits(a), &f == fields ? v.min_hits : v.min_hits / 4) << what;  // (min_hits: for the blobs)
      std::printf("%s: %zu hits\n", what.c_str(), hits(a));
      // The pass did its job, not only no harm: seen from far, most of the image's tiles miss
      // the grid and are left out.
      if (v.dist_m >= 0.2) {
        EXPECT_GT(culled, std::size_t(v.w * v.h) / 2) << what << ": tiles left out";
      }
      expect_gpu_matches_cpu(a, cpu, 1.0 / 0.8e-3, what.c_str());
    }
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

namespace {

/// The trilinear field of `f` in double at a continuous index (voxels outside the grid read
/// the background), written here from the definition, not from the caster's code.
double field_double(const RaycastField& f, const Vec3& p) {
  const double fl[3] = {std::floor(p.x), std::floor(p.y), std::floor(p.z)};
  const double fr[3] = {p.x - fl[0], p.y - fl[1], p.z - fl[2]};
  const auto& n = f.grid.dims;
  double sum = 0;
  for (int c = 0; c < 8; ++c) {
    const int i = int(fl[0]) + (c & 1), j = int(fl[1]) + (c >> 1 & 1), k = int(fl[2]) + (c >> 2 & 1);
    const bool in = i >= 0 && j >= 0 && k >= 0 && i < n[0] && j < n[1] && k < n[2];
    const double v = in ? double(f.values[f.grid.index(i, j, k)]) : double(f.background);
    const double w = ((c & 1) ? fr[0] : 1 - fr[0]) * ((c >> 1 & 1) ? fr[1] : 1 - fr[1]) * ((c >> 2 & 1) ? fr[2] : 1 - fr[2]);
    sum += w * v;
  }
  return sum;
}

/// Distance [voxels along the ray] from depth t to the nearest entering crossing of the
/// isosurface (outside -> inside) of the double-precision field within `reach` voxels
/// (sampled every reach / 64, the crossing then bisected in double); +inf if none.
double distance_to_crossing(const RaycastField& f, const CameraView& view, const Vec3& dir, double t, double reach) {
  const double vpm = engine::voxels_per_metre(f.grid, dir);
  auto excess = [&](double s) {
    return f.iso.excess(field_double(f, f.grid.to_index(view.eye + dir * s)));
  };
  const int n = 128;
  const double step = 2 * reach / n / vpm, s0 = t - reach / vpm;
  double best = std::numeric_limits<double>::infinity();
  double prev = excess(s0);
  for (int i = 1; i <= n; ++i) {
    double a = s0 + (i - 1) * step, b = s0 + i * step;
    const double eb = excess(b);
    if (!(prev > 0) && eb > 0) {
      for (int k = 0; k < 60; ++k) {
        const double m = 0.5 * (a + b);
        (excess(m) > 0 ? b : a) = m;
      }
      best = std::min(best, std::fabs(0.5 * (a + b) - t) * vpm);
    }
    prev = eb;
  }
  return best;
}

}  // namespace

// The refinement's claim (raycast.h: the hit refined to under 0.01 voxel along the ray),
// on CT data whose surface curves within a cell: every hit pixel of the head and chest CTs
// (GPU, several cameras) lies within 0.01 voxel of a point where the ray enters the
// isosurface of the trilinear field evaluated in double here (truth outside the caster).
TEST(Raycast, HitsLieOnTheIsosurfaceOfTheDoubleField) {
  struct Case {
    std::string path;
    core::Isosurface iso;
  };
  const Case cases[] = {{kHead, {1150, core::InsideIs::kAbove}},
                        {kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd",
                         {-500, core::InsideIs::kAbove}}};
  for (const Case& c : cases) {
    const engine::Volume vol = io::load_volume(c.path);
    const RaycastField f = engine::make_raycast_field(vol.grid, vol.voxels, c.iso,
                                                      float(c.iso.outside_value(vol.min_value, vol.max_value)));
    auto rc = engine::RayCaster::create(vk(), f);
    ASSERT_TRUE(rc) << rc.error;
    std::size_t checked = 0, off = 0;
    std::vector<double> errs;
    for (double az : {0.0, 37.0, 121.0, 250.0}) {
      engine::OrbitCamera cam = run::default_camera(vol);
      cam.azimuth_deg += az;
      cam.elevation_deg = az > 100 ? -25 : 20;
      cam.zoom = 1.6;
      const CameraView view = engine::orbit_view(f.grid, vol.direction, cam);
      const int W = 160, H = 120;
      const RaycastImage g = (*rc.value)->render(view, RaycastStyle{}, W, H);
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const float t = g.depth[std::size_t(y) * W + std::size_t(x)];
          if (t < 0) continue;
          const double e = distance_to_crossing(f, view, engine::pixel_direction(view, W, H, x, y), t, 0.05);
          errs.push_back(std::min(e, 1.0));
          off += !(e <= 0.01);
          ++checked;
        }
    }
    std::sort(errs.begin(), errs.end());
    ASSERT_GT(checked, 4000u) << c.path;
    std::printf("%s: %zu hits, distance to the double field's crossing median %.2g, p99.9 %.2g, worst %.2g voxel, "
                "%zu over 0.01\n", c.path.c_str(), checked, errs[errs.size() / 2], errs[errs.size() * 999 / 1000],
                errs.back(), off);
    EXPECT_EQ(off, 0u) << c.path << ": hits farther than 0.01 voxel from the isosurface along their rays";
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

namespace {
/// The raw 32-bit pixels of a device buffer (copied to a readback buffer here).
std::vector<std::uint32_t> read_device_pixels(VkBuffer src, std::size_t n) {
  engine::GpuBuffer down = engine::make_buffer_or_throw(vk(), n * 4, engine::MemoryIntent::Readback, "test readback");
  VkCommandBuffer cmd = vk().begin_commands();
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &mb, 0, nullptr, 0,
                       nullptr);
  const VkBufferCopy region{0, 0, n * 4};
  vkCmdCopyBuffer(cmd, src, down.handle(), 1, &region);
  mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
  vk().submit_and_wait(cmd);
  std::vector<std::uint32_t> out(n);
  std::memcpy(out.data(), down.mapped(), n * 4);
  return out;
}
}  // namespace

// A picture kept on the device (what isotouch-sculpt copies into its swapchain image) is the
// one render() copies out: in the device buffer byte for byte, or with red and blue swapped
// (BGRA), the background and the overlay included; last_rgba() gives it back as RGBA and
// last_depth() every pixel's depth; nothing is copied into the RaycastImage.
TEST(Raycast, PictureKeptOnTheDeviceIsTheCopiedOne) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  const Vec3 front = s.centre() + Vec3{0, -s.r_m, 0};
  const std::vector<gpu::RaycastPrim> prims = {
      engine::prim_sphere(front + Vec3{0.006, -0.004, 0.004}, 0.004, {0.15f, 0.8f, 0.25f}),
      engine::prim_sphere(front, 0.01, {0.3f, 0.5f, 0.9f}, 0.35f)};
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& caster = **rc.value;
  const int W = 90, H = 70;
  const std::size_t n = std::size_t(W) * H;
  const RaycastImage copied = caster.render(view, RaycastStyle{}, W, H, prims);
  ASSERT_EQ(copied.rgba.size(), n);
  auto swap = [](std::uint32_t p) { return (p & 0xFF00FF00u) | ((p & 0xFFu) << 16) | ((p >> 16) & 0xFFu); };
  std::size_t grey = 0;  // pixels whose red and blue are equal (the swap cannot show there)
  for (std::uint32_t p : copied.rgba) grey += p == swap(p);
  EXPECT_LT(grey, n / 2) << "too few coloured pixels to tell the orders apart";
  caster.set_in_place(true);
  for (bool bgra : {true, false}) {
    caster.set_bgra(bgra);
    const RaycastImage kept = caster.render(view, RaycastStyle{}, W, H, prims);
    EXPECT_TRUE(kept.rgba.empty() && kept.depth.empty());
    EXPECT_EQ(kept.width, W);
    const std::vector<std::uint32_t> raw = read_device_pixels(caster.image_buffer(), n);
    std::size_t wrong = 0, depth_wrong = 0;
    for (std::size_t i = 0; i < n; ++i) wrong += raw[i] != (bgra ? swap(copied.rgba[i]) : copied.rgba[i]);
    EXPECT_EQ(wrong, 0u) << (bgra ? "BGRA" : "RGBA") << ": device pixels not the copied picture in that order";
    EXPECT_EQ(caster.last_rgba(), copied.rgba);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) depth_wrong += caster.last_depth(x, y) != copied.depth[std::size_t(y) * W + std::size_t(x)];
    EXPECT_EQ(depth_wrong, 0u);
  }
  EXPECT_THROW(caster.last_depth(W, 0), std::out_of_range);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

// Host work given to render() runs once, while the frame is drawn (between the submit and the
// wait), and changes nothing in the picture; one that throws passes its exception on and
// leaves the caster and its context usable (the submission was waited for).
TEST(Raycast, HostWorkDuringTheFrameRunsOnceAndKeepsThePicture) {
  const SphereCase s;
  const RaycastField f = s.field();
  const CameraView view = s.view(0.25, 40);
  auto rc = engine::RayCaster::create(vk(), f);
  ASSERT_TRUE(rc) << rc.error;
  engine::RayCaster& caster = **rc.value;
  const RaycastImage plain = caster.render(view, RaycastStyle{}, 80, 60);
  int runs = 0;
  // Another camera first, so that `with` is drawn whole, as `plain` was (not reused).
  (void)caster.render(s.view(0.3, 40), RaycastStyle{}, 80, 60);
  // The host work sleeps 30 ms: counted in the submit-to-wait time, it ran after the submit.
  const RaycastImage with = caster.render(view, RaycastStyle{}, 80, 60, {}, [&] {
    ++runs;
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
  });
  EXPECT_EQ(runs, 1);
  EXPECT_GE(with.submit_wall_ms, 30.0) << "the host work did not run between the submit and the wait";
  EXPECT_EQ(with.rgba, plain.rgba);
  EXPECT_EQ(with.depth, plain.depth);
  EXPECT_THROW(caster.render(s.view(0.3, 40), RaycastStyle{}, 80, 60, {}, [] { throw std::runtime_error("meanwhile"); }),
               std::runtime_error);
  const RaycastImage after = caster.render(view, RaycastStyle{}, 80, 60);
  EXPECT_EQ(after.rgba, plain.rgba);
  EXPECT_EQ(vk().validation_messages(), 0u);
}
