// Brushes: every brush on the GPU against the CPU reference bit for bit
// (lavapipe), on a synthetic volume and the head CT, at the border, straddling brick
// borders, with small bindings (z-chunks); the CPU reference against brute-force formulas
// written here in double (falloff profile of a carve on a constant volume, add never past
// the target, drill threshold and density, smooth's neighbour mean, inside "below"); the
// dirty set against a brute-force diff; validation layer on, no message allowed.
#include <limits>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <set>

#include "isotouch/tests/vk_test_context.h"
#include "isotouch/tests/gpu_cpu_compare.h"
#include "isotouch/core/brick_field.h"
#include "isotouch/session/brush.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"

using namespace isotouch;
using session::Brush;
using session::BrushKind;
using engine::Volume;

namespace {
const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kHead = kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
const std::string kChest = kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd";

engine::VulkanContext& vk() { return test::validated_vk(); }

constexpr BrushKind kKinds[] = {BrushKind::kAdd, BrushKind::kCarve, BrushKind::kSmooth, BrushKind::kDrill};

Brush make(BrushKind k, core::Vec3 c, double radius, const session::BrushTargets& t) {
  Brush b;
  b.kind = k;
  b.centre_m = c;
  b.radius_m = radius;
  b.targets = t;
  b.falloff = 0.6;
  b.strength = k == BrushKind::kSmooth ? 0.7 : 0.25 * std::abs(double(t.material) - double(t.empty));
  b.force_n = 3.0;
  b.force_threshold_n = 1.0;
  b.rate = 0.5 * std::abs(double(t.material) - double(t.empty)) / (2.0 * 1e-3);  // half the span per 2 N-ms
  b.dt_s = 1e-3;
  return b;
}

/// Bricks where some voxel's bits differ (brute force over the whole volume).
std::vector<std::uint32_t> diff_bricks(const Volume& a, const std::vector<float>& b) {
  std::set<std::uint32_t> s;
  const auto nb = core::brick_counts(a.grid);
  for (int z = 0; z < a.grid.dims[2]; ++z)
    for (int y = 0; y < a.grid.dims[1]; ++y)
      for (int x = 0; x < a.grid.dims[0]; ++x) {
        const std::size_t i = a.grid.index(x, y, z);
        if (std::bit_cast<std::uint32_t>(a.voxels[i]) != std::bit_cast<std::uint32_t>(b[i]))
          s.insert(std::uint32_t(((z / 8) * nb[1] + y / 8) * nb[0] + x / 8));
      }
  return {s.begin(), s.end()};
}

std::size_t bits_differ(const std::vector<float>& a, const std::vector<float>& b) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.size(); ++i) n += std::bit_cast<std::uint32_t>(a[i]) != std::bit_cast<std::uint32_t>(b[i]);
  return n;
}

/// Applies the brushes in turn on the GPU (with the host mirror) and the CPU; after each
/// one: GPU volume == mirror == CPU bit for bit, dirty sets equal and equal to the diff.
void gpu_vs_cpu(const Volume& start, const std::vector<Brush>& brushes, std::uint64_t max_binding = 0,
                bool expect_chunks = false) {
  auto eng = session::BrushEngine::create(vk(), start, max_binding);
  ASSERT_TRUE(eng) << eng.error;
  Volume cpu = start, mirror = start;
  for (std::size_t i = 0; i < brushes.size(); ++i) {
    const Brush& b = brushes[i];
    SCOPED_TRACE(std::string(to_string(b.kind)) + " #" + std::to_string(i));
    const std::vector<float> before = cpu.voxels, mirror_before = mirror.voxels;
    const auto rc = session::apply_brush_cpu(cpu, b);
    const auto rg = (*eng.value)->apply(b, &mirror);
    EXPECT_EQ(rg.touched, rc.touched);
    EXPECT_EQ(rc.dirty, diff_bricks(cpu, before)) << "dirty set differs from the brute-force diff";
    EXPECT_EQ(rg.dirty, diff_bricks(mirror, mirror_before)) << "GPU dirty set differs from the brute-force diff";
    const std::vector<float> device = (*eng.value)->download_all();
    EXPECT_TRUE(test::gpu_matches_cpu(vk(), device, cpu.voxels, "GPU volume vs CPU reference"));
    EXPECT_EQ(bits_differ(mirror.voxels, device), 0u) << "host mirror (dirty bricks downloaded) vs the device copy";
    if (test::expects_bit_identity(vk())) {
      EXPECT_EQ(rg.dirty, rc.dirty);
    } else {
      cpu = mirror;  // a GPU may differ by ULPs: the next brush starts both from the GPU's result
    }
    if (expect_chunks) {
      EXPECT_GT(rg.dispatches, 1u);
    }
  }
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

/// Brushes of every kind at the centre, near each border, straddling brick borders.
std::vector<Brush> brush_set(const Volume& v, const session::BrushTargets& t, double radius) {
  const core::Grid& g = v.grid;
  std::vector<core::Vec3> at = {
      g.centre_m(),
      g.to_world({8.0, 8.0, 8.0}),                          // brick corner: 8 bricks meet
      g.to_world({7.5, 15.5, 8.2}),                         // straddles x and y brick borders
      g.to_world({0.0, 0.0, 0.0}),                          // volume corner
      g.to_world({double(g.dims[0]) - 1.0, g.dims[1] / 2.0, double(g.dims[2]) - 0.6}),  // far faces
      g.to_world({-2.0, g.dims[1] / 3.0, g.dims[2] / 2.0}), // centre outside the grid, reaching in
  };
  std::vector<Brush> out;
  for (const auto& c : at)
    for (BrushKind k : kKinds) out.push_back(make(k, c, radius, t));
  return out;
}

TEST(Brush, GpuMatchesCpuBitForBitOnRandomVolume) {
  Volume v = engine::make_random({37, 29, 21}, {1e-3, 1.3e-3, 0.9e-3}, -500.0f, 1500.0f, 7);
  v.update_stats();
  const auto t = session::default_targets(v, {300.0, core::InsideIs::kAbove});
  gpu_vs_cpu(v, brush_set(v, t, 6e-3));
}

TEST(Brush, GpuMatchesCpuBitForBitOnHeadCt) {
  Volume v = io::load_volume(kHead);
  const auto t = session::default_targets(v, {1150.0, core::InsideIs::kAbove});
  auto set = brush_set(v, t, 10e-3);
  auto small = brush_set(v, t, 3e-3);
  set.insert(set.end(), small.begin(), small.end());
  gpu_vs_cpu(v, set);
}

TEST(Brush, SmallBindingsSplitIntoChunksAndStillMatch) {
  Volume v = io::load_volume(kHead);
  const auto t = session::default_targets(v, {1150.0, core::InsideIs::kAbove});
  // 64 x 64 floats = 16 KiB per slice: 200 KiB holds 1 brick layer (+ 2 halo slices).
  std::vector<Brush> b;
  for (BrushKind k : kKinds) b.push_back(make(k, v.grid.centre_m(), 30e-3, t));
  gpu_vs_cpu(v, b, 200 * 1024, true);
}

TEST(Brush, InsideBelowSignedDistance) {
  // SDF, negative inside: material negative, empty positive.
  Volume v = engine::make_sphere({33, 33, 33}, 1e-3, 10.0);
  for (float& x : v.voxels) x = -x;
  v.update_stats();
  const core::Isosurface iso{0.0, core::InsideIs::kBelow};
  const auto t = session::default_targets(v, iso);
  EXPECT_LT(t.material, 0.0f);
  EXPECT_GT(t.empty, 0.0f);
  gpu_vs_cpu(v, brush_set(v, t, 5e-3));
  // A strong carve at the sphere's centre removes the inside there; a strong add on the
  // empty corner makes material.
  Volume c = v;
  Brush carve = make(BrushKind::kCarve, v.grid.centre_m(), 4e-3, t);
  carve.strength = 1e6;
  session::apply_brush_cpu(c, carve);
  EXPECT_FALSE(iso.contains(c.voxels[v.grid.index(16, 16, 16)]));
  EXPECT_EQ(c.voxels[v.grid.index(16, 16, 16)], t.empty);
  Brush add = make(BrushKind::kAdd, v.grid.to_world({2, 2, 2}), 3e-3, t);
  add.strength = 1e6;
  session::apply_brush_cpu(c, add);
  EXPECT_TRUE(iso.contains(c.voxels[v.grid.index(2, 2, 2)]));
}

// Independent formula: w(r) = 1 - smoothstep(inner, R, r), inner = R (1 - falloff), in double.
double w_ref(double r, double R, double falloff) {
  if (r >= R) return 0;
  const double inner = R * (1 - falloff);
  const double t = std::clamp((r - inner) / (R - inner), 0.0, 1.0);
  return 1 - t * t * (3 - 2 * t);
}
double dist_m(const core::Grid& g, int x, int y, int z, core::Vec3 c) {
  const core::Vec3 p = g.to_world({double(x), double(y), double(z)});
  return std::sqrt((p.x - c.x) * (p.x - c.x) + (p.y - c.y) * (p.y - c.y) + (p.z - c.z) * (p.z - c.z));
}

TEST(Brush, CarveOnConstantVolumeIsTheFalloffProfile) {
  Volume v = engine::make_linear({30, 30, 30}, {1e-3, 1.5e-3, 0.8e-3}, {0, 0, 0}, 1000.0);
  const session::BrushTargets t{1000.0f, 0.0f, 1000.0f};
  const core::Vec3 c = v.grid.to_world({14.3, 12.6, 15.1});
  Brush b = make(BrushKind::kCarve, c, 9e-3, t);
  b.strength = 400;
  b.falloff = 0.7;
  session::apply_brush_cpu(v, b);
  int inside = 0;
  for (int z = 0; z < 30; ++z)
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 30; ++x) {
        const double r = dist_m(v.grid, x, y, z, c);
        const double want = 1000.0 - 400.0 * w_ref(r, 9e-3, 0.7);
        const float got = v.voxels[v.grid.index(x, y, z)];
        // float distance and weight: |dw/dr| <= 1.5 / (R falloff) per metre, r to ~1e-6 relative.
        ASSERT_NEAR(got, want, 0.01) << "voxel " << x << "," << y << "," << z << " r " << r;
        inside += r < 9e-3 * 0.3;
      }
  EXPECT_GT(inside, 10);  // the plateau (w = 1) was sampled
}

TEST(Brush, AddNeverExceedsTheTarget) {
  Volume v = engine::make_random({24, 24, 24}, {1e-3, 1e-3, 1e-3}, 0.0f, 900.0f, 3);
  const session::BrushTargets t{1000.0f, -1000.0f, 2000.0f};
  const Volume start = v;
  Brush b = make(BrushKind::kAdd, v.grid.centre_m(), 8e-3, t);
  b.strength = 333;
  for (int k = 0; k < 6; ++k) session::apply_brush_cpu(v, b);
  int at_target = 0;
  for (std::size_t i = 0; i < v.voxels.size(); ++i) {
    ASSERT_LE(v.voxels[i], 1000.0f);
    ASSERT_GE(v.voxels[i], start.voxels[i]);  // add only ever moves toward material
    at_target += v.voxels[i] == 1000.0f;
  }
  EXPECT_GT(at_target, 100);
  // A single application moves by strength * w, clamped (brute force on every voxel).
  Volume one = start;
  session::apply_brush_cpu(one, b);
  for (int z = 0; z < 24; ++z)
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 24; ++x) {
        const std::size_t i = v.grid.index(x, y, z);
        const double want = std::min(double(start.voxels[i]) + 333.0 * w_ref(dist_m(v.grid, x, y, z, b.centre_m), 8e-3, b.falloff), 1000.0);
        ASSERT_NEAR(one.voxels[i], want, 0.01);
      }
}

TEST(Brush, DrillThresholdAndDensity) {
  // Two halves: soft tissue (40) for x < 12, bone (1500) for x >= 12; empty = -1000 (air).
  Volume v = engine::make_linear({24, 24, 24}, {1e-3, 1e-3, 1e-3}, {0, 0, 0}, 40.0);
  for (int z = 0; z < 24; ++z)
    for (int y = 0; y < 24; ++y)
      for (int x = 12; x < 24; ++x) v.voxels[v.grid.index(x, y, z)] = 1500.0f;
  const session::BrushTargets t{3000.0f, -1000.0f, 1000.0f};
  Brush b = make(BrushKind::kDrill, v.grid.to_world({11.5, 12, 12}), 5e-3, t);
  b.rate = 2e5;  // [HU / (N s)]
  b.dt_s = 1e-3;
  // At or below the threshold nothing is removed.
  for (double f : {0.0, 0.5, 1.0}) {
    b.force_n = f;
    Volume w = v;
    const auto r = session::apply_brush_cpu(w, b);
    EXPECT_TRUE(r.dirty.empty());
    EXPECT_EQ(bits_differ(w.voxels, v.voxels), 0u);
  }
  b.force_n = 3.0;  // 2 N above: a = 2e5 * 1e-3 * 2 = 400 HU at w = 1, density factor 1
  Volume w = v;
  session::apply_brush_cpu(w, b);
  const int y = 12, z = 12;
  const std::size_t soft = v.grid.index(11, y, z), bone = v.grid.index(12, y, z);  // same distance 0.5 mm
  const double removed_soft = 40.0 - w.voxels[soft], removed_bone = 1500.0 - w.voxels[bone];
  EXPECT_GT(removed_soft, 0);
  EXPECT_GT(removed_bone, 0);
  EXPECT_LT(removed_bone, removed_soft) << "bone must be drilled more slowly than soft tissue";
  const double wgt = w_ref(0.5e-3, 5e-3, b.falloff);
  EXPECT_NEAR(removed_soft, 400.0 * wgt / (1 + 1040.0 / 1000.0), 0.01);
  EXPECT_NEAR(removed_bone, 400.0 * wgt / (1 + 2500.0 / 1000.0), 0.01);
  // Never below empty, however long it drills.
  b.force_n = 1e3;
  for (int k = 0; k < 5; ++k) session::apply_brush_cpu(w, b);
  for (float x : w.voxels) ASSERT_GE(x, -1000.0f);
  EXPECT_EQ(w.voxels[soft], -1000.0f);
}

TEST(Brush, SmoothBlendsTowardTheNeighbourMeanOfThePreEditVolume) {
  Volume v = engine::make_random({20, 18, 17}, {1e-3, 1e-3, 1e-3}, -100.0f, 100.0f, 11);
  const Volume start = v;
  Brush b = make(BrushKind::kSmooth, v.grid.to_world({1.0, 9.0, 8.0}), 5e-3, {1.0f, 0.0f, 1.0f});
  b.strength = 0.8;
  session::apply_brush_cpu(v, b);
  const auto& g = v.grid;
  auto at = [&](int x, int y, int z) {
    x = std::clamp(x, 0, g.dims[0] - 1);
    y = std::clamp(y, 0, g.dims[1] - 1);
    z = std::clamp(z, 0, g.dims[2] - 1);
    return double(start.voxels[g.index(x, y, z)]);
  };
  for (int z = 0; z < g.dims[2]; ++z)
    for (int y = 0; y < g.dims[1]; ++y)
      for (int x = 0; x < g.dims[0]; ++x) {
        const double m = (at(x - 1, y, z) + at(x + 1, y, z) + at(x, y - 1, z) + at(x, y + 1, z) + at(x, y, z - 1) +
                          at(x, y, z + 1)) / 6.0;
        const double w = w_ref(dist_m(g, x, y, z, b.centre_m), 5e-3, b.falloff);
        const double want = at(x, y, z) + (m - at(x, y, z)) * 0.8 * w;
        ASSERT_NEAR(v.voxels[g.index(x, y, z)], want, 1e-3) << x << "," << y << "," << z;
      }
}

// A NaN voxel (a masked CT): smoothing leaves its neighbours as they are instead of
// spreading the NaN (mutation: dropping the finite check turns its 6 neighbours NaN);
// GPU and CPU agree bit for bit on it.
TEST(Brush, SmoothDoesNotSpreadNaN) {
  Volume v = engine::make_random({20, 18, 17}, {1e-3, 1e-3, 1e-3}, -100.0f, 100.0f, 12);
  v.voxels[v.grid.index(10, 9, 8)] = std::numeric_limits<float>::quiet_NaN();
  Brush b = make(BrushKind::kSmooth, v.grid.to_world({10.0, 9.0, 8.0}), 4e-3, {1.0f, 0.0f, 1.0f});
  b.strength = 0.8;
  gpu_vs_cpu(v, {b});
  Volume cpu = v;
  session::apply_brush_cpu(cpu, b);
  std::size_t nan = 0;
  for (float x : cpu.voxels) nan += std::isnan(x) ? 1 : 0;
  EXPECT_EQ(nan, 1u) << "smoothing spread the NaN voxel";
  const int nb[6][3] = {{9, 9, 8}, {11, 9, 8}, {10, 8, 8}, {10, 10, 8}, {10, 9, 7}, {10, 9, 9}};
  for (const auto& q : nb)
    EXPECT_EQ(std::bit_cast<std::uint32_t>(cpu.voxels[v.grid.index(q[0], q[1], q[2])]),
              std::bit_cast<std::uint32_t>(v.voxels[v.grid.index(q[0], q[1], q[2])]));
}

// A blank canvas (no material: every voxel outside): "add" must still create material.
TEST(Brush, DefaultTargetsOnABlankCanvasAreInside) {
  Volume v = engine::make_random({16, 16, 16}, {1e-3, 1e-3, 1e-3}, 0.0f, 0.0f, 1);
  v.min_value = 0.0f;
  v.max_value = 0.0f;
  const core::Isosurface above{0.5, core::InsideIs::kAbove}, below{-0.5, core::InsideIs::kBelow};
  EXPECT_TRUE(above.contains(session::default_targets(v, above).material));
  EXPECT_FALSE(above.contains(session::default_targets(v, above).empty));
  EXPECT_TRUE(below.contains(session::default_targets(v, below).material));
  EXPECT_FALSE(below.contains(session::default_targets(v, below).empty));
}

TEST(Brush, TouchedBricksCoverTheBrushAndMissOutside) {
  Volume v = engine::make_random({40, 40, 40}, {1e-3, 1e-3, 1e-3}, 0.0f, 1.0f, 1);
  Brush b = make(BrushKind::kCarve, v.grid.to_world({7.9, 8.0, 30.0}), 3e-3, {1.0f, 0.0f, 1.0f});
  const auto ids = session::touched_bricks(v.grid, b);
  // Every voxel within the radius lies in a touched brick (brute force).
  const auto nb = core::brick_counts(v.grid);
  for (int z = 0; z < 40; ++z)
    for (int y = 0; y < 40; ++y)
      for (int x = 0; x < 40; ++x)
        if (dist_m(v.grid, x, y, z, b.centre_m) < 3e-3) {
          const std::uint32_t id = std::uint32_t(((z / 8) * nb[1] + y / 8) * nb[0] + x / 8);
          ASSERT_TRUE(std::binary_search(ids.begin(), ids.end(), id)) << x << "," << y << "," << z;
        }
  b.centre_m = v.grid.to_world({-10, 5, 5});
  EXPECT_TRUE(session::touched_bricks(v.grid, b).empty());
  auto eng = session::BrushEngine::create(vk(), v);
  ASSERT_TRUE(eng) << eng.error;
  EXPECT_TRUE((*eng.value)->apply(b).dirty.empty());
}

TEST(Brush, InvalidBrushNamesTheField) {
  Volume v = engine::make_random({8, 8, 8}, {1e-3, 1e-3, 1e-3}, 0.0f, 1.0f, 1);
  Brush b = make(BrushKind::kSmooth, v.grid.centre_m(), 2e-3, {1.0f, 0.0f, 1.0f});
  b.strength = 2;
  EXPECT_NE(session::validate(b).find("'strength'"), std::string::npos);
  b.strength = 0.5;
  b.radius_m = -1;
  EXPECT_NE(session::validate(b).find("'radius_m'"), std::string::npos);
  b.radius_m = 1e-3;
  b.falloff = 0;
  EXPECT_NE(session::validate(b).find("'falloff'"), std::string::npos);
  b.falloff = 0.5;
  b.centre_m.x = std::nan("");
  EXPECT_THROW(session::apply_brush_cpu(v, b), session::BrushError);
}

// Not an assertion: time per application on the chest CT, GPU (this device) and CPU,
// radii 2, 5, 10 mm, median of repeated applications. Printed for the report.
// A Sculptor with a device picks the path per brush by touched bricks: small ones on the
// CPU reference (the device copy marked stale), large ones on the device (stale bricks
// uploaded first), undo in between. Truth: a CPU-only Sculptor given the same brushes, bit
// for bit after each; the device copy equals the host; the path taken is the one asked for.
TEST(Brush, SculptorMixesCpuAndDevicePathsBitForBit) {
  if (!test::expects_bit_identity(vk())) GTEST_SKIP() << "this device is not bit-identical to the CPU reference";
  Volume v = io::load_volume(kHead);
  const auto t = session::default_targets(v, {1150.0, core::InsideIs::kAbove});
  session::Sculptor mixed(v, &vk(), 64.0), ref(v, nullptr, 64.0);
  mixed.set_cpu_max_bricks(8);
  EXPECT_FALSE(ref.on_gpu());
  const core::Vec3 c = v.grid.centre_m();
  // Overlapping small and large brushes of every kind: each large one reads voxels the
  // small ones before it changed on the host only.
  std::vector<Brush> seq;
  for (int k = 0; k < 4; ++k) {
    seq.push_back(make(kKinds[k], c + core::Vec3{0.002 * k, 0.0, 0.0}, 4e-3, t));
    seq.push_back(make(kKinds[(k + 1) % 4], c + core::Vec3{0.002 * k, 0.001, 0.0}, 12e-3, t));
  }
  std::size_t cpu_runs = 0, device_runs = 0;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    SCOPED_TRACE(std::string(to_string(seq[i].kind)) + " #" + std::to_string(i));
    const std::size_t touched = session::touched_range(v.grid, seq[i]).count();
    const auto rm = mixed.apply(seq[i]);
    const auto rr = ref.apply(seq[i]);
    EXPECT_EQ(rm.on_device, touched > 8) << touched << " touched bricks";
    EXPECT_FALSE(rr.on_device);
    (rm.on_device ? device_runs : cpu_runs) += rm.dirty.empty() ? 0 : 1;  // runs that changed voxels
    EXPECT_EQ(rm.dirty, rr.dirty);
    ASSERT_EQ(bits_differ(mixed.volume().voxels, ref.volume().voxels), 0u) << "mixed paths vs the CPU reference";
    if (i == 4) {  // undo restores on the host; the device copy follows at its next use
      EXPECT_EQ(mixed.undo(), ref.undo());
      ASSERT_EQ(bits_differ(mixed.volume().voxels, ref.volume().voxels), 0u) << "after undo";
    }
  }
  EXPECT_GT(cpu_runs, 0u);
  EXPECT_GT(device_runs, 0u);
  ASSERT_NE(mixed.engine(), nullptr);
  EXPECT_EQ(mixed.stale_on_device(), 0u) << "engine() uploads the stale bricks";
  EXPECT_EQ(bits_differ(mixed.engine()->download_all(), ref.volume().voxels), 0u) << "device copy vs host";
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(Brush, DISABLED_BenchChest) {  // run with --gtest_also_run_disabled_tests
  Volume v = io::load_volume(kChest);
  const auto t = session::default_targets(v, {-500.0, core::InsideIs::kAbove});
  engine::ContextOptions o;
  auto ctx = engine::VulkanContext::create(o);  // no validation layer: it would time itself
  ASSERT_TRUE(ctx) << ctx.error;
  auto eng = session::BrushEngine::create(**ctx.value, v);
  ASSERT_TRUE(eng) << eng.error;
  Volume mirror = v, cpu = v;
  auto median = [](std::vector<double> x) {
    std::sort(x.begin(), x.end());
    return x[x.size() / 2];
  };
  for (double radius_mm : {2.0, 5.0, 10.0})
    for (BrushKind k : kKinds) {
      Brush b = make(k, v.grid.to_world({128.0, 128.0, 32.0}), radius_mm * 1e-3, t);  // on a voxel
      std::vector<double> gw, gg, cw;
      std::size_t touched = 0, dirty = 0;
      for (int rep = 0; rep < 9; ++rep) {
        const auto rg = (*eng.value)->apply(b, &mirror);
        const auto rc = session::apply_brush_cpu(cpu, b);
        gw.push_back(rg.wall_ms);
        gg.push_back(rg.gpu_ms);
        cw.push_back(rc.wall_ms);
        touched = rc.touched.size();
        dirty = rc.dirty.size();
      }
      std::printf("chest 256x256x64, %s r=%.0f mm: %zu touched bricks, %zu dirty; GPU wall %.3f ms (dispatch %.3f ms), CPU %.3f ms (median of 9)\n",
                  to_string(k), radius_mm, touched, dirty, median(gw), median(gg), median(cw));
    }
  EXPECT_EQ(bits_differ(mirror.voxels, cpu.voxels), 0u);
}

}  // namespace
