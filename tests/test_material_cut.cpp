// Per-material drilling and the critical margin on analytic layered phantoms whose truth
// is exact (labels made here from the geometry, not by the code under test):
//  - a critical tube inside a bone slab, drilled toward from 8 directions: no critical voxel
//    changes, and the margin warning fires before the burr reaches the tube, in every drill
//    (reach judged by brute force over the tube's voxels);
//  - a soft layer above a hard one: the soft one loses value faster by the ratio of the
//    rates, and two materials differing in density_scale by the ratio of their density
//    factors (tolerances from the brush's float formula);
//  - the distance field against brute force (also an oblique shape on three different
//    spacings); a cut of label 0 only is bit for bit no cut;
//  - a Sculptor with a Vulkan device and a cut keeps every brush on the CPU reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdint>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

#include "isotouch/materials/critical_distance.h"
#include "isotouch/materials/critical_margin.h"
#include "isotouch/session/brush.h"
#include "isotouch/tests/vk_test_context.h"

using namespace isotouch;
using core::Vec3;
using session::Brush;
using session::BrushKind;
using session::CutMaterial;
using session::MaterialCut;

namespace {
constexpr float kBone = 1000.0f, kEmpty = 0.0f;
constexpr std::uint8_t kSlab = 1, kTube = 2;

/// A bone slab (the whole grid, value 1000) with a critical tube along x through the grid's
/// centre, radius tube_r_m, on an anisotropic grid.
struct TubePhantom {
  engine::Volume vol;
  std::shared_ptr<MaterialCut> cut = std::make_shared<MaterialCut>();
  double tube_r_m = 2.5e-3;
  Vec3 axis_point;                      ///< a point on the tube's axis [m]
  std::vector<Vec3> tube_voxels;        ///< centres of the tube's voxels [m]
  std::vector<std::size_t> tube_index;  ///< their offsets

  TubePhantom() {
    vol.grid.dims = {24, 56, 52};
    vol.grid.spacing_m = {0.5e-3, 0.5e-3, 0.55e-3};
    vol.path = "synthetic:tube-phantom";
    vol.voxels.assign(vol.grid.voxel_count(), kBone);
    vol.update_stats();
    axis_point = vol.grid.centre_m();
    cut->ids.assign(vol.grid.voxel_count(), kSlab);
    cut->table = {CutMaterial{4000, 0, false}, CutMaterial{4000, 0, true}};
    const auto& g = vol.grid;
    for (int z = 0; z < g.dims[2]; ++z)
      for (int y = 0; y < g.dims[1]; ++y)
        for (int x = 0; x < g.dims[0]; ++x) {
          const Vec3 p = g.to_world(Vec3{double(x), double(y), double(z)});
          if (std::hypot(p.y - axis_point.y, p.z - axis_point.z) < tube_r_m) {
            cut->ids[g.index(x, y, z)] = kTube;
            tube_voxels.push_back(p);
            tube_index.push_back(g.index(x, y, z));
          }
        }
  }
  /// Exact distance from p to the nearest tube voxel centre (brute force) [m].
  double exact_distance(const Vec3& p) const {
    double best = 1e9;
    for (const Vec3& q : tube_voxels) best = std::min(best, core::norm(p - q));
    return best;
  }
};

Brush drill_at(const Vec3& c, double radius_m, double force_n) {
  Brush b;
  b.kind = BrushKind::kDrill;
  b.centre_m = c;
  b.radius_m = radius_m;
  b.falloff = 0.5;
  b.targets = {kBone, kEmpty, 1000.0f};
  b.force_n = force_n;
  b.force_threshold_n = 1.0;
  b.rate = 4000;
  b.dt_s = 1e-2;
  return b;
}

std::vector<bool> critical_flags(const MaterialCut& cut) {
  std::vector<bool> f(cut.table.size() + 1, false);
  for (std::size_t i = 0; i < cut.table.size(); ++i) f[i + 1] = cut.table[i].critical;
  return f;
}
}  // namespace

// The distance field: a lower bound of the brute-force distance everywhere (also outside the
// grid), exact at voxel centres, at most one cell diagonal short between them.
TEST(MaterialCut, CriticalDistanceMatchesBruteForce) {
  const TubePhantom ph;
  const materials::CriticalDistance cd(ph.vol.grid, ph.cut->ids, critical_flags(*ph.cut));
  ASSERT_TRUE(cd.any());
  const auto& g = ph.vol.grid;
  const double diag = core::norm(g.spacing_m);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-2.0, 1.0);
  for (int i = 0; i < 300; ++i) {
    const Vec3 f{u(rng) + 0.5, u(rng) + 0.5, u(rng) + 0.5};  // some points outside the grid
    const Vec3 idx{f.x * g.dims[0], f.y * g.dims[1], f.z * g.dims[2]};
    const Vec3 p = g.to_world(idx);
    const double exact = ph.exact_distance(p), lb = cd.lower_bound(p);
    EXPECT_LE(lb, exact + 1e-6) << "at index " << idx.x << " " << idx.y << " " << idx.z;
    const bool inside = idx.x >= 0 && idx.y >= 0 && idx.z >= 0 && idx.x <= g.dims[0] - 1 && idx.y <= g.dims[1] - 1 &&
                        idx.z <= g.dims[2] - 1;
    if (inside) {
      EXPECT_GE(lb, exact - diag - 1e-6) << "at index " << idx.x << " " << idx.y << " " << idx.z;
    }
  }
  for (int i = 0; i < 200; ++i) {
    const int x = int(rng() % unsigned(g.dims[0])), y = int(rng() % unsigned(g.dims[1])), z = int(rng() % unsigned(g.dims[2]));
    const double exact = ph.exact_distance(g.to_world(Vec3{double(x), double(y), double(z)}));
    EXPECT_NEAR(cd.at(x, y, z), exact, 1e-6 + 1e-6 * exact) << x << " " << y << " " << z;
  }
}

// 8 drills toward the tube, perpendicular to its axis, the burr advancing 0.1 mm per
// application at 3 N: the slab is removed up to the tube, no tube voxel changes, and the
// margin (1.5 mm) warns as the burr's surface enters it, before its sphere holds any tube
// voxel centre.
TEST(MaterialCut, DrillsTowardTheTubeNeverTouchItAndWarnFirst) {
  TubePhantom ph;
  const materials::CriticalDistance cd(ph.vol.grid, ph.cut->ids, critical_flags(*ph.cut));
  const double burr_r = 1.5e-3, margin = 1.5e-3, step = 0.1e-3;
  const double diag = core::norm(ph.vol.grid.spacing_m);
  for (int dir = 0; dir < 8; ++dir) {
    engine::Volume vol = ph.vol;
    const double a = dir * std::numbers::pi / 4;
    const Vec3 u{0, std::cos(a), std::sin(a)};  // from the axis outward
    materials::CriticalMargin warn(margin);
    int warned_at = -1, reached_at = -1;
    double surface_at_warning = 0;  // the exact surface distance when the warning fired [m]
    long removed = 0;
    for (int k = 0;; ++k) {
      const double from_axis = 10e-3 - k * step;
      if (from_axis < 1e-3) break;  // the centre well inside the tube
      const Vec3 c = ph.axis_point + u * from_axis;
      if (warn.update(k * 1e-2, 1e-2, cd.lower_bound(c) - burr_r) && warned_at < 0) {
        warned_at = k;
        surface_at_warning = ph.exact_distance(c) - burr_r;
      }
      if (reached_at < 0 && ph.exact_distance(c) < burr_r) reached_at = k;
      session::apply_brush_cpu(vol, drill_at(c, burr_r, 3.0), ph.cut.get());
    }
    for (std::size_t i : ph.tube_index) ASSERT_EQ(vol.voxels[i], kBone) << "direction " << dir << ": tube voxel " << i;
    for (std::size_t i = 0; i < vol.voxels.size(); ++i) removed += vol.voxels[i] < kBone ? 1 : 0;
    EXPECT_GT(removed, 100) << "direction " << dir << ": the drill removed no slab";
    ASSERT_GE(reached_at, 0) << "direction " << dir;
    EXPECT_GE(warned_at, 0) << "direction " << dir << ": no warning";
    EXPECT_LT(warned_at, reached_at) << "direction " << dir;
    // It fires as the surface enters the margin: not before (the distance is a lower bound,
    // at most a cell diagonal short), and at most one step after.
    EXPECT_GE(surface_at_warning, margin - step - 1e-9) << "direction " << dir;
    EXPECT_LT(surface_at_warning, margin + diag) << "direction " << dir;
    EXPECT_GE(warn.entries(), 1) << "direction " << dir;
    EXPECT_LT(warn.closest_m(), 0.0) << "direction " << dir << ": the burr overlapped the tube's centres";
  }
}

// The monitor's figures on a hand-made approach: out, in twice, out.
TEST(MaterialCut, MarginCountsEntriesTimeAndClosest) {
  materials::CriticalMargin m(1e-3);
  const double d[] = {3e-3, 2e-3, 0.9e-3, 0.4e-3, 1.2e-3, 0.8e-3, 2e-3};
  for (int k = 0; k < 7; ++k) m.update(k * 0.01, 0.01, d[k]);
  EXPECT_EQ(m.entries(), 2);
  EXPECT_NEAR(m.time_inside_s(), 0.03, 1e-12);
  EXPECT_EQ(m.closest_m(), 0.4e-3);
  EXPECT_EQ(m.first_entry_t_s(), 0.02);
  EXPECT_FALSE(m.inside());
}

// A carve over the tube leaves it too.
TEST(MaterialCut, CarveLeavesTheCriticalTube) {
  TubePhantom ph;
  Brush b = drill_at(ph.axis_point, 4e-3, 0);
  b.kind = BrushKind::kCarve;
  b.strength = 1e4;
  session::apply_brush_cpu(ph.vol, b, ph.cut.get());
  for (std::size_t i : ph.tube_index) ASSERT_EQ(ph.vol.voxels[i], kBone);
  EXPECT_EQ(ph.vol.voxels[ph.vol.grid.index(12, 28, 26 + 6)], kEmpty);  // 3.6 mm from the axis: slab, removed
}

// Soft above hard, the interface midway between two voxel layers and the burr centred on it:
// mirrored voxels have the same weight and value, so each soft voxel loses rate_s / rate_h
// times what its hard mirror loses (per voxel: float(a_i * w) / f, as brush.h's formula).
TEST(MaterialCut, SoftLayerGoesFasterByTheRateRatio) {
  engine::Volume vol;
  vol.grid.dims = {24, 24, 24};
  vol.grid.spacing_m = {0.5e-3, 0.5e-3, 0.5e-3};
  vol.path = "synthetic:soft-over-hard";
  vol.voxels.assign(vol.grid.voxel_count(), kBone);
  vol.update_stats();
  auto cut = std::make_shared<MaterialCut>();
  const double rate_soft = 3000, rate_hard = 500;
  cut->table = {CutMaterial{rate_soft, 0, false}, CutMaterial{rate_hard, 0, false}};
  cut->ids.resize(vol.grid.voxel_count());
  for (int z = 0; z < 24; ++z)
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 24; ++x) cut->ids[vol.grid.index(x, y, z)] = z >= 12 ? 1 : 2;  // soft above z = 11.5
  const Vec3 c = vol.grid.to_world(Vec3{11.5, 11.5, 11.5});
  const Brush b = drill_at(c, 2e-3, 1.5);  // small removal: no voxel reaches empty
  const engine::Volume before = vol;
  session::apply_brush_cpu(vol, b, cut.get());
  int pairs = 0;
  for (int dz = 0; dz < 12; ++dz)
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 24; ++x) {
        const std::size_t s = vol.grid.index(x, y, 12 + dz), h = vol.grid.index(x, y, 11 - dz);
        const double ds = double(before.voxels[s]) - vol.voxels[s], dh = double(before.voxels[h]) - vol.voxels[h];
        const double ratio = rate_soft / rate_hard, half_ulp = 6.1035e-5;  // ulp(1000) / 2
        if (dh == 0) {  // a hard step below the float resolution at 1000
          EXPECT_LE(ds, ratio * 2 * half_ulp);
          continue;
        }
        ++pairs;
        // Each removal is float(float(a_i * w) / f) (a_i = float(rate_i dt (|F| - F_t)), the
        // same w and f for a voxel and its mirror) subtracted from 1000 in float: relative
        // errors of 3 roundings (2^-24 each) per side, and half an ulp of 1000 absolute.
        const double rel = 6 * 5.97e-8 + half_ulp / (ratio * dh) + half_ulp / dh;
        EXPECT_NEAR(ds / dh, ratio, ratio * rel) << x << " " << y << " " << dz;
      }
  EXPECT_GT(pairs, 50);
}

// Label 0 everywhere takes the brush's own constants: bit for bit the brush without a cut.
TEST(MaterialCut, LabelZeroIsTheOneMaterialBrush) {
  TubePhantom ph;
  MaterialCut none = *ph.cut;
  std::fill(none.ids.begin(), none.ids.end(), std::uint8_t(0));
  engine::Volume a = ph.vol, b = ph.vol;
  for (int k = 0; k < 20; ++k) {
    const Brush br = drill_at(ph.axis_point + Vec3{0, 4e-3 - k * 2e-4, 0}, 2e-3, 2.5);
    session::apply_brush_cpu(a, br);
    session::apply_brush_cpu(b, br, &none);
  }
  ASSERT_EQ(a.voxels.size(), b.voxels.size());
  EXPECT_EQ(std::memcmp(a.voxels.data(), b.voxels.data(), a.voxels.size() * sizeof(float)), 0);
  // A material without its own rate or density scale (rate < 0, density_scale 0) drills as
  // the brush does.
  MaterialCut own = *ph.cut;
  std::fill(own.ids.begin(), own.ids.end(), kSlab);
  own.table[0] = CutMaterial{-1, 0, false};
  engine::Volume c = ph.vol;
  for (int k = 0; k < 20; ++k)
    session::apply_brush_cpu(c, drill_at(ph.axis_point + Vec3{0, 4e-3 - k * 2e-4, 0}, 2e-3, 2.5), &own);
  EXPECT_EQ(std::memcmp(a.voxels.data(), c.voxels.data(), a.voxels.size() * sizeof(float)), 0);
}

TEST(MaterialCut, BadCutIsRefusedNamingTheField) {
  TubePhantom ph;
  MaterialCut bad = *ph.cut;
  bad.ids[5] = 9;
  EXPECT_NE(session::validate(bad, bad.ids.size()).find("field 'ids': voxel 5 has label 9"), std::string::npos);
  // The brush checks the sizes only (the Sculptor validates once); an id past the table under
  // the brush is left unchanged.
  const std::size_t under = ph.vol.grid.index(12, 28, 26 + 6);  // slab, 3.6 mm from the axis
  bad.ids[under] = 9;
  engine::Volume vol = ph.vol;
  session::apply_brush_cpu(vol, drill_at(ph.axis_point, 4e-3, 50), &bad);
  EXPECT_EQ(vol.voxels[under], kBone) << "a voxel of an unknown label was changed";
  EXPECT_LT(vol.voxels[ph.vol.grid.index(12, 28, 26 - 6)], kBone) << "the test's premise: the drill removes its mirror";
  bad.ids.pop_back();
  try {
    session::apply_brush_cpu(vol, drill_at(ph.axis_point, 1e-3, 2), &bad);
    ADD_FAILURE() << "no error";
  } catch (const session::BrushError& e) {
    EXPECT_NE(std::string(e.what()).find("field 'ids' holds"), std::string::npos) << e.what();
  }
  bad = *ph.cut;
  bad.table[0].rate = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(session::validate(bad, bad.ids.size()).find("material 1: field 'rate' must be finite"), std::string::npos);
  bad = *ph.cut;
  bad.table[1].density_scale = 1e-39;  // its inverse is past a float
  EXPECT_NE(session::validate(bad, bad.ids.size()).find("material 2: field 'density_scale'"), std::string::npos);
}

// Smooth and add change no critical voxel either: smoothing next to a hole would pull the
// tube's voxels toward empty, adding would raise them.
TEST(MaterialCut, SmoothAndAddLeaveTheCriticalTube) {
  TubePhantom ph;
  const auto& g = ph.vol.grid;
  for (int z = 0; z < g.dims[2]; ++z)  // a hole above the tube's axis (slab only)
    for (int y = 0; y < g.dims[1]; ++y)
      for (int x = 0; x < g.dims[0]; ++x)
        if (ph.cut->ids[g.index(x, y, z)] == kSlab && g.to_world(Vec3{double(x), double(y), double(z)}).z > ph.axis_point.z)
          ph.vol.voxels[g.index(x, y, z)] = kEmpty;
  for (std::size_t i : ph.tube_index) ph.vol.voxels[i] = 800.0f;
  const engine::Volume before = ph.vol;
  Brush smooth = drill_at(ph.axis_point, 4e-3, 0);
  smooth.kind = BrushKind::kSmooth;
  smooth.strength = 1;
  Brush add = smooth;
  add.kind = BrushKind::kAdd;
  add.strength = 100;
  for (const Brush& b : {smooth, add}) {
    engine::Volume plain = before, cut = before;
    session::apply_brush_cpu(plain, b);
    session::apply_brush_cpu(cut, b, ph.cut.get());
    int would_change = 0;
    for (std::size_t i : ph.tube_index) {
      would_change += plain.voxels[i] != before.voxels[i];
      ASSERT_EQ(cut.voxels[i], before.voxels[i]) << (b.kind == BrushKind::kSmooth ? "smooth" : "add");
    }
    EXPECT_GT(would_change, 10) << "the test's premise: without the cut the brush changes the tube";
  }
}

// A Sculptor with a device and a cut: every brush on the CPU reference (the shader has no
// labels), the same bits as apply_brush_cpu with the cut, even when told to send all to the device.
TEST(MaterialCut, SculptorWithCutStaysOnTheCpuReference) {
  TubePhantom ph;
  session::Sculptor s(ph.vol, &test::validated_vk());
  s.set_material_cut(ph.cut);
  s.set_cpu_max_bricks(0);
  engine::Volume ref = ph.vol;
  for (int k = 0; k < 30; ++k) {
    const Brush b = drill_at(ph.axis_point + Vec3{0, 0, 6e-3 - k * 2e-4}, 2e-3, 3.0);
    const session::BrushResult r = s.apply(b);
    EXPECT_FALSE(r.on_device);
    session::apply_brush_cpu(ref, b, ph.cut.get());
  }
  EXPECT_EQ(std::memcmp(s.volume().voxels.data(), ref.voxels.data(), ref.voxels.size() * sizeof(float)), 0);
  EXPECT_EQ(test::validated_vk().validation_messages(), 0u);
}

// The distance transform on a grid with three different spacings, for an oblique shape (a
// tube along (1, 2, 3) plus a ball off its axis): every voxel's distance is the brute-force
// distance to the shape's voxel centres. An axis run with another axis's spacing would miss.
TEST(MaterialCut, CriticalDistanceIsExactOnAnObliqueShapeWithThreeSpacings) {
  core::Grid g;
  g.dims = {20, 17, 15};
  g.spacing_m = {0.3e-3, 0.5e-3, 0.8e-3};
  std::vector<std::uint8_t> ids(g.voxel_count(), 1);
  const Vec3 p0 = g.to_world(Vec3{2, 3, 1}), dir = Vec3{1, 2, 3} * (1 / std::sqrt(14.0));
  const Vec3 ball = g.to_world(Vec3{16, 4, 11});
  std::vector<Vec3> shape;
  for (int z = 0; z < g.dims[2]; ++z)
    for (int y = 0; y < g.dims[1]; ++y)
      for (int x = 0; x < g.dims[0]; ++x) {
        const Vec3 p = g.to_world(Vec3{double(x), double(y), double(z)});
        const Vec3 d = p - p0;
        const bool tube = core::norm(d - dir * core::dot(d, dir)) < 0.6e-3;
        if (tube || core::norm(p - ball) < 1.0e-3) {
          ids[g.index(x, y, z)] = 2;
          shape.push_back(p);
        }
      }
  ASSERT_GT(shape.size(), 20u);
  const materials::CriticalDistance cd(g, ids, {false, false, true});
  for (int z = 0; z < g.dims[2]; ++z)
    for (int y = 0; y < g.dims[1]; ++y)
      for (int x = 0; x < g.dims[0]; ++x) {
        const Vec3 p = g.to_world(Vec3{double(x), double(y), double(z)});
        double exact = 1e9;
        for (const Vec3& q : shape) exact = std::min(exact, core::norm(p - q));
        ASSERT_NEAR(cd.at(x, y, z), exact, 1e-7 + 1e-6 * exact) << x << " " << y << " " << z;
      }
}

// Per-material density_scale: two materials of the same rate, mirrored about the burr's
// centre, differ only in density_scale. Each loses amount * w / f with f = 1 + (v - empty) /
// density_scale (brush.h), so a voxel of A loses f_B / f_A times what its mirror of B loses.
TEST(MaterialCut, DensityScaleScalesTheRemovedAmount) {
  engine::Volume vol;
  vol.grid.dims = {24, 24, 24};
  vol.grid.spacing_m = {0.5e-3, 0.5e-3, 0.5e-3};
  vol.path = "synthetic:two-densities";
  vol.voxels.assign(vol.grid.voxel_count(), kBone);
  vol.update_stats();
  auto cut = std::make_shared<MaterialCut>();
  const double ds_a = 4000, ds_b = 250;
  cut->table = {CutMaterial{4000, ds_a, false}, CutMaterial{4000, ds_b, false}};
  cut->ids.resize(vol.grid.voxel_count());
  for (int z = 0; z < 24; ++z)
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 24; ++x) cut->ids[vol.grid.index(x, y, z)] = z >= 12 ? 1 : 2;
  const Brush b = drill_at(vol.grid.to_world(Vec3{11.5, 11.5, 11.5}), 2e-3, 1.5);
  const engine::Volume before = vol;
  session::apply_brush_cpu(vol, b, cut.get());
  const double ratio = (1 + kBone / ds_b) / (1 + kBone / ds_a);
  const double half_ulp = 6.1035e-5;  // ulp(1000) / 2
  int pairs = 0;
  for (int dz = 0; dz < 12; ++dz)
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 24; ++x) {
        const std::size_t s = vol.grid.index(x, y, 12 + dz), h = vol.grid.index(x, y, 11 - dz);
        const double da = double(before.voxels[s]) - vol.voxels[s], db = double(before.voxels[h]) - vol.voxels[h];
        if (db == 0) {
          EXPECT_LE(da, ratio * 2 * half_ulp);
          continue;
        }
        ++pairs;
        // float(float(a * w) / f) with f's own 3 roundings (inverse, product, sum) per side,
        // subtracted from 1000 in float: 6 relative roundings and half an ulp of 1000.
        const double rel = 10 * 5.97e-8 + half_ulp / (ratio * db) + half_ulp / db;
        EXPECT_NEAR(da / db, ratio, ratio * rel) << x << " " << y << " " << dz;
      }
  EXPECT_GT(pairs, 50);
}
