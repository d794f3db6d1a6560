// test_field_view.cpp - core::FieldView and core::Isosurface against brute force written
// here from the definitions: trilinear weights per corner, the voxel
// outside the grid = {background, 0, 0, 0}, the excess sign rule.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>

#include "isotouch/core/brick_field.h"
#include "isotouch/core/field_view.h"
#include "isotouch/servo/hri.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/sample_field.h"

namespace isotouch {
namespace {
using core::FieldView;
using core::InsideIs;
using core::Isosurface;
using core::Sample;
using core::SampleField;
using core::Vec3;

SampleField random_field(std::array<int, 3> dims, float background, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  SampleField f;
  f.grid.dims = dims;
  f.grid.spacing_m = {1e-3, 2e-3, 1.5e-3};
  f.grid.origin_m = {0.01, -0.02, 0.003};
  f.samples.resize(f.grid.voxel_count());
  for (Sample& s : f.samples) s = {float(500 * u(rng)), float(u(rng)), float(u(rng)), float(u(rng))};
  f.background = background;
  return f;
}

// The definition: voxel (x, y, z) is the sample inside the grid, {background, 0, 0, 0} outside.
Sample brute_voxel(const SampleField& f, long x, long y, long z) {
  const auto& d = f.grid.dims;
  if (x < 0 || y < 0 || z < 0 || x >= d[0] || y >= d[1] || z >= d[2]) return {f.background, 0, 0, 0};
  return f.samples[f.grid.index(int(x), int(y), int(z))];
}

// Trilinear by the weight formula: sum over the 8 corners of floor(idx) of w * voxel;
// on a 1-voxel axis inside [0, 0] the weight is all on voxel 0.
template <class Get>
double brute_trilinear(const SampleField& f, const Vec3& world, Get get) {
  const Vec3 idx = f.grid.to_index(world);
  double sum = 0;
  long i0[3];
  double fr[3];
  for (int a = 0; a < 3; ++a) {
    const double v = idx[a];
    const int n = f.grid.dims[a];
    i0[a] = long(std::floor(v));
    if (v == n - 1 && n > 1) i0[a] = n - 2;  // the last cell holds its upper face
    fr[a] = v - double(i0[a]);
  }
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const double w = (i ? fr[0] : 1 - fr[0]) * (j ? fr[1] : 1 - fr[1]) * (k ? fr[2] : 1 - fr[2]);
        if (w == 0) continue;
        sum += w * get(brute_voxel(f, i0[0] + i, i0[1] + j, i0[2] + k));
      }
  return sum;
}

TEST(FieldView, ValueAndGradientMatchTheDefinitionInsideAtTheBorderAndOutside) {
  const SampleField f = random_field({7, 5, 4}, -250.0f, 1);
  const FieldView v(f);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-0.5, 1.5);  // -50 % .. 150 % of the extent
  const Vec3 ext = f.grid.extent_m();
  int outside = 0, band = 0;
  for (int k = 0; k < 5000; ++k) {
    const Vec3 x = f.grid.origin_m + Vec3{ext.x * u(rng), ext.y * u(rng), ext.z * u(rng)};
    const double bv = brute_trilinear(f, x, [](const Sample& s) { return double(s.value); });
    ASSERT_NEAR(v.value(x), bv, 1e-9) << k;
    const core::FieldValue fv = v.value_gradient(x);
    ASSERT_NEAR(fv.value, bv, 1e-9) << k;
    ASSERT_NEAR(fv.gradient.x, brute_trilinear(f, x, [](const Sample& s) { return double(s.gx); }), 1e-12);
    ASSERT_NEAR(fv.gradient.z, brute_trilinear(f, x, [](const Sample& s) { return double(s.gz); }), 1e-12);
    const Vec3 i = f.grid.to_index(x);
    const bool out = i.x < 0 || i.y < 0 || i.z < 0 || i.x > 6 || i.y > 4 || i.z > 3;
    outside += out;
    band += out && i.x > -1 && i.y > -1 && i.z > -1 && i.x < 7 && i.y < 5 && i.z < 4;
  }
  EXPECT_GT(outside, 1000);  // the border path was exercised, blends included
  EXPECT_GT(band, 100);
  // Far away: exactly the background; not clamp-to-edge.
  EXPECT_EQ(v.value(f.grid.origin_m + Vec3{1, 1, 1}), -250.0);
  EXPECT_EQ(v.value(f.grid.origin_m - Vec3{1e300, 0, 0}), -250.0);
}

// central_difference is ((f(x + h_x) - f(x - h_x)) / (2 h_x), ...) of the trilinear value at the
// six points, each read as value_at_index reads one point: bit for bit, whether the points share
// their cells (a dense field, half-voxel steps: the x-lerps of the y and z pairs are shared) or
// not (the border, other steps), on cell faces too (where a point's cell is the upper one).
TEST(FieldView, CentralDifferenceIsTheSixValuesBitForBit) {
  const SampleField f = random_field({9, 7, 6}, -250.0f, 5);
  const FieldView v(f);
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> u(-0.2, 1.2);
  const Vec3 ext = f.grid.extent_m();
  auto bits = [](double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; };
  long inside = 0;
  for (int k = 0; k < 20000; ++k) {
    Vec3 x = f.grid.origin_m + Vec3{ext.x * u(rng), ext.y * u(rng), ext.z * u(rng)};
    if (k % 4 == 1) {  // on voxel centres or half-voxel faces: the six points on cell faces
      const Vec3 i = f.grid.to_index(x);
      x = f.grid.to_world({std::round(2 * i.x) / 2, std::round(2 * i.y) / 2, i.z});
    }
    const double hv = k % 3 == 2 ? 0.3 : 0.5;  // the renderers' half voxel, and another step
    const Vec3 h = f.grid.spacing_m * hv;
    const Vec3 g = v.central_difference(x, h);
    const Vec3 i = f.grid.to_index(x);
    const Vec3 hi{h.x / f.grid.spacing_m.x, h.y / f.grid.spacing_m.y, h.z / f.grid.spacing_m.z};
    const Vec3 want{(v.value_at_index({i.x + hi.x, i.y, i.z}) - v.value_at_index({i.x - hi.x, i.y, i.z})) / (2 * h.x),
                    (v.value_at_index({i.x, i.y + hi.y, i.z}) - v.value_at_index({i.x, i.y - hi.y, i.z})) / (2 * h.y),
                    (v.value_at_index({i.x, i.y, i.z + hi.z}) - v.value_at_index({i.x, i.y, i.z - hi.z})) / (2 * h.z)};
    ASSERT_TRUE(bits(g.x, want.x) && bits(g.y, want.y) && bits(g.z, want.z))
        << k << ": (" << g.x << ", " << g.y << ", " << g.z << ") vs (" << want.x << ", " << want.y << ", " << want.z
        << ")";
    inside += i.x >= hi.x && i.y >= hi.y && i.z >= hi.z && i.x + hi.x <= 8 && i.y + hi.y <= 6 && i.z + hi.z <= 5;
  }
  EXPECT_GT(inside, 4000);  // every point in the grid: the shared reads were exercised
}

// change_bound_in_cell bounds the change of the value between any points of a segment in
// one cell (the reads at 7 interior points and both ends, as HRI's god-object test reads),
// and answers +inf for a segment that leaves its cell or has a NaN corner.
TEST(FieldView, ChangeBoundInCellBoundsEveryReadOnTheSegment) {
  SampleField f = random_field({9, 7, 6}, -250.0f, 7);
  const FieldView v(f);
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  long bounded = 0;
  for (int k = 0; k < 20000; ++k) {
    const Vec3 cell{double(int(7 * u(rng))), double(int(5 * u(rng))), double(int(4 * u(rng)))};
    const double len = k % 2 ? 0.05 : 1.2;  // short: mostly in one cell; long: mostly not
    const Vec3 ia = cell + Vec3{u(rng), u(rng), u(rng)};
    const Vec3 ib = ia + Vec3{len * (u(rng) - 0.5), len * (u(rng) - 0.5), len * (u(rng) - 0.5)};
    const Vec3 a = f.grid.to_world(ia), b = f.grid.to_world(ib);
    const double bound = v.change_bound_in_cell(a, b);
    const bool same = std::floor(ia.x) == std::floor(ib.x) && std::floor(ia.y) == std::floor(ib.y) &&
                      std::floor(ia.z) == std::floor(ib.z);
    if (!same) {
      EXPECT_TRUE(std::isinf(bound)) << k;
    }
    if (std::isinf(bound)) continue;
    ++bounded;
    const double va = v.value(a);
    for (int i = 1; i <= 8; ++i) ASSERT_LE(std::abs(v.value(a + (b - a) * (i / 8.0)) - va), bound) << k << " " << i;
    // and the reads HRI's god-object test makes when the bound does not decide (FieldView::Segment)
    FieldView::Segment seg(v, a, b);
    for (int i = 1; i <= 7; ++i) ASSERT_LE(std::abs(seg.value(i / 8.0) - va), bound) << k << " " << i;
  }
  EXPECT_GT(bounded, 8000);
  // An end within the 1e-9 voxel margin of a cell face, on either side of it: no bound; an
  // end 2e-9 voxel inside the face: a bound. Every axis, lower and upper face, both sides.
  for (int k = 0; k < 2400; ++k) {
    const Vec3 ia{1.0 + 5 * u(rng), 1.0 + 3 * u(rng), 1.0 + 2 * u(rng)};
    const int axis = k % 3, upper = (k / 3) % 2;
    const double beyond = (k / 6) % 2 ? 0.5e-9 : -0.5e-9;  // > 0: past the face, out of the cell
    Vec3 end = ia;
    double& c = axis == 0 ? end.x : axis == 1 ? end.y : end.z;
    const double face = std::floor(ia[axis]) + upper;
    const double out = upper ? 1.0 : -1.0;  // the direction out of the cell across that face
    c = face + out * beyond;
    EXPECT_TRUE(std::isinf(v.change_bound_in_cell(f.grid.to_world(ia), f.grid.to_world(end)))) << k;
    c = face - out * 2e-9;
    EXPECT_FALSE(std::isinf(v.change_bound_in_cell(f.grid.to_world(ia), f.grid.to_world(end)))) << k;
  }
  f.samples[f.grid.index(2, 2, 2)].value = std::numeric_limits<float>::quiet_NaN();
  const FieldView w(f);
  EXPECT_TRUE(std::isinf(w.change_bound_in_cell(f.grid.to_world({2.5, 2.5, 2.5}), f.grid.to_world({2.6, 2.5, 2.5}))));
  // A NaN end, either one: no bound (std::min / std::max would have dropped it).
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Vec3 in_cell = f.grid.to_world({3.5, 3.5, 3.5});
  EXPECT_TRUE(std::isinf(v.change_bound_in_cell(in_cell, {nan, nan, nan})));
  EXPECT_TRUE(std::isinf(v.change_bound_in_cell({nan, nan, nan}, in_cell)));
}

// FieldView::cell_range: the cell that value() interpolates at the point (floor of its
// index), its 8 corners' least and largest values from the definition, a box that holds the
// point and only points of that cell, and every value read in the box within the corners'
// range to rounding; the same on an fp32 bricked field. No cell for a point within the
// margin of a face, off the box of voxel centres, not finite, or with a NaN corner, nor on a
// 1-voxel axis or an empty view.
TEST(FieldView, CellRangeHoldsEveryReadInItsBox) {
  SampleField f = random_field({9, 7, 6}, -250.0f, 11);
  const core::BrickedInput in = core::bricked_input_from_dense(f, Isosurface{0.0, InsideIs::kAbove});
  const SampleField b32 = core::make_bricked_field(in, core::SampleFormat::kFp32);
  const FieldView v(f), vb(b32);
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto brute_floor = [&](const Vec3& w) {
    const Vec3 i = f.grid.to_index(w);
    return std::array<long, 3>{long(std::floor(i.x)), long(std::floor(i.y)), long(std::floor(i.z))};
  };
  long found = 0;
  for (int k = 0; k < 5000; ++k) {
    const Vec3 idx{8.0 * u(rng), 6.0 * u(rng), 5.0 * u(rng)};
    const Vec3 w = f.grid.to_world(idx);
    Vec3 lo, hi, lo_b, hi_b;
    double vlo = 0, vhi = 0, vlo_b = 0, vhi_b = 0;
    const bool ok = v.cell_range(w, lo, hi, vlo, vhi);
    ASSERT_EQ(ok, vb.cell_range(w, lo_b, hi_b, vlo_b, vhi_b)) << k;
    if (!ok) continue;
    ++found;
    EXPECT_TRUE(lo.x == lo_b.x && lo.y == lo_b.y && lo.z == lo_b.z && hi.x == hi_b.x && hi.y == hi_b.y && hi.z == hi_b.z);
    EXPECT_EQ(vlo, vlo_b);
    EXPECT_EQ(vhi, vhi_b);
    const std::array<long, 3> c = brute_floor(w);
    double mn = INFINITY, mx = -INFINITY;
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const double s = brute_voxel(f, c[0] + dx, c[1] + dy, c[2] + dz).value;
          mn = std::min(mn, s);
          mx = std::max(mx, s);
        }
    ASSERT_EQ(vlo, mn) << k;
    ASSERT_EQ(vhi, mx) << k;
    ASSERT_TRUE(w.x >= lo.x && w.y >= lo.y && w.z >= lo.z && w.x <= hi.x && w.y <= hi.y && w.z <= hi.z) << k;
    const double tol = 1e-12 * std::max(std::abs(mn), std::abs(mx));
    for (int j = 0; j < 20; ++j) {
      // Random points of the box, its corners among them: in the same cell, read in range.
      const Vec3 t = j < 8 ? Vec3{double(j & 1), double((j >> 1) & 1), double(j >> 2)} : Vec3{u(rng), u(rng), u(rng)};
      const Vec3 q{lo.x + (hi.x - lo.x) * t.x, lo.y + (hi.y - lo.y) * t.y, lo.z + (hi.z - lo.z) * t.z};
      ASSERT_EQ(brute_floor(q), c) << k << " " << j;
      const double val = v.value(q);
      ASSERT_GE(val, mn - tol) << k << " " << j;
      ASSERT_LE(val, mx + tol) << k << " " << j;
    }
  }
  EXPECT_GT(found, 4900);
  Vec3 lo, hi;
  double vlo = 0, vhi = 0;
  for (const Vec3& idx : {Vec3{2.0, 3.5, 2.5}, Vec3{2.5, 3.0 + 1e-10, 2.5}, Vec3{2.5, 3.5, 3.0 - 1e-10},
                          Vec3{-0.1, 3.5, 2.5}, Vec3{8.0, 3.5, 2.5}, Vec3{2.5, 6.5, 2.5}})
    EXPECT_FALSE(v.cell_range(f.grid.to_world(idx), lo, hi, vlo, vhi)) << idx.x << " " << idx.y << " " << idx.z;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(v.cell_range({nan, 0.0, 0.0}, lo, hi, vlo, vhi));
  f.samples[f.grid.index(3, 3, 3)].value = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(FieldView(f).cell_range(f.grid.to_world({2.5, 2.5, 2.5}), lo, hi, vlo, vhi));  // corner (3, 3, 3)
  EXPECT_TRUE(FieldView(f).cell_range(f.grid.to_world({1.5, 1.5, 1.5}), lo, hi, vlo, vhi));
  const SampleField flat = random_field({9, 7, 1}, 0.0f, 13);
  EXPECT_FALSE(FieldView(flat).cell_range(flat.grid.to_world({2.5, 2.5, 0.0}), lo, hi, vlo, vhi));
  EXPECT_FALSE(FieldView(SampleField{}).cell_range({0.0, 0.0, 0.0}, lo, hi, vlo, vhi));
}

// FieldView::Segment reads the value at ia + (ib - ia) t as value_at_index reads that index,
// to rounding (its cubic per cell against the lerps), whether consecutive reads stay in one
// cell or move (back and forth, as a root search does), on dense, bricked fp32 and fp16
// fields, in the border band, outside and for NaN; and within rounding of value() at
// a + (b - a) t.
TEST(FieldView, SegmentReadsAreValueAtIndexToRounding) {
  SampleField dense = random_field({19, 11, 10}, -250.0f, 9);
  dense.samples[dense.grid.index(4, 4, 4)].value = std::numeric_limits<float>::quiet_NaN();
  const core::BrickedInput in = core::bricked_input_from_dense(dense, Isosurface{0.0, InsideIs::kAbove});
  const SampleField b32 = core::make_bricked_field(in, core::SampleFormat::kFp32);
  const SampleField b16 = core::make_bricked_field(in, core::SampleFormat::kFp16);
  std::mt19937 rng(10);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  long reused = 0, moved = 0, nan_reads = 0;
  double worst = 0;
  auto on_face = [](const Vec3& i) {
    for (int a = 0; a < 3; ++a)
      if (std::abs(i[a] - std::round(i[a])) < 1e-9) return true;
    return false;
  };
  const SampleField* fields[] = {&dense, &b32, &b16};
  for (const SampleField* f : fields) {
    const FieldView v(*f);
    for (int k = 0; k < 3000; ++k) {
      // Segments from a fraction of a voxel to several voxels long, a few off the grid.
      const Vec3 ia{-1.5 + 21 * u(rng), -1.5 + 13 * u(rng), -1.5 + 12 * u(rng)};
      const double len = k % 3 == 0 ? 0.3 : (k % 3 == 1 ? 2.0 : 6.0);
      const Vec3 ib = ia + Vec3{len * (u(rng) - 0.5), len * (u(rng) - 0.5), len * (u(rng) - 0.5)};
      const Vec3 a = f->grid.to_world(ia), b = f->grid.to_world(ib);
      const Vec3 ja = f->grid.to_index(a), d = f->grid.to_index(b) - ja;
      FieldView::Segment seg(v, a, b);
      int last[3] = {-9, -9, -9};
      for (int i = 0; i < 40; ++i) {
        // A march (i / 32), then jumps back and forth (a bracket's reads).
        const double t = i < 33 ? i / 32.0 : u(rng) * 1.2 - 0.1;
        const Vec3 idx{ja.x + d.x * t, ja.y + d.y * t, ja.z + d.z * t};
        const double got = seg.value(t), want = v.value_at_index(idx);
        if (std::isnan(want) || std::isnan(got)) {
          // A NaN corner's cell reads NaN; on a face the neighbour's cubic may answer.
          ASSERT_TRUE((std::isnan(want) && std::isnan(got)) || on_face(idx)) << k << " " << i << ": " << got << " vs " << want;
          ++nan_reads;
        } else {
          ASSERT_NEAR(got, want, 1e-10) << k << " " << i;
          worst = std::max(worst, std::abs(got - want));
          const double world = v.value(a + (b - a) * t);
          if (!std::isnan(world)) {
            ASSERT_NEAR(got, world, 1e-9) << k << " " << i;
          }
        }
        const int c[3] = {int(std::floor(idx.x)), int(std::floor(idx.y)), int(std::floor(idx.z))};
        const bool same = c[0] == last[0] && c[1] == last[1] && c[2] == last[2];
        reused += same;
        moved += !same;
        for (int a2 = 0; a2 < 3; ++a2) last[a2] = c[a2];
      }
    }
  }
  EXPECT_GT(reused, 50000);  // reads in the loaded cell were exercised
  EXPECT_GT(moved, 50000);   // and reads that load another one
  EXPECT_GT(nan_reads, 10);  // the NaN corner's cell was read
  std::printf("largest |Segment - value_at_index|: %.3g (corners up to 500)\n", worst);
  // A 1-voxel axis: a line along it is in the grid only where its index is 0, elsewhere
  // it reads the border (a blend with the background), and a line in its plane is a cubic.
  const SampleField thin = random_field({6, 1, 3}, 40.0f, 11);
  const FieldView tv(thin);
  for (int k = 0; k < 200; ++k) {
    const Vec3 ia{0.5 + 4 * u(rng), k % 2 ? -0.5 : 0.0, 0.5 + u(rng)};
    const Vec3 ib = ia + Vec3{u(rng) - 0.5, k % 2 ? 1.0 : 0.0, u(rng) - 0.5};
    const Vec3 a = thin.grid.to_world(ia), b = thin.grid.to_world(ib);
    const Vec3 ja = thin.grid.to_index(a), d = thin.grid.to_index(b) - ja;
    FieldView::Segment seg(tv, a, b);
    for (int i = 0; i <= 8; ++i) {
      const double t = i / 8.0;
      const Vec3 idx{ja.x + d.x * t, ja.y + d.y * t, ja.z + d.z * t};
      ASSERT_NEAR(seg.value(t), tv.value_at_index(idx), 1e-10) << k << " " << i;
    }
  }
  // An empty view reads NaN.
  const FieldView empty;
  FieldView::Segment none(empty, Vec3{}, Vec3{1, 1, 1});
  EXPECT_TRUE(std::isnan(none.value(0.5)));
}

TEST(FieldView, ExactTrilinearGradientIsTheDerivativeOfTheValue) {
  const SampleField f = random_field({6, 1, 3}, 40.0f, 3);  // a 1-voxel axis too
  const FieldView v(f);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.02, 0.98);
  for (int k = 0; k < 500; ++k) {
    // Inside cells, off the cell faces (the derivative jumps there); y on its only plane.
    const Vec3 i{std::floor(6 * u(rng) - 0.5) + u(rng), 0.0, std::floor(3 * u(rng) - 0.5) + u(rng)};
    const Vec3 x = f.grid.to_world(i);
    const Vec3 g = v.trilinear_gradient(x);
    const double h = 1e-7;
    const Vec3 hx{h, 0, 0}, hz{0, 0, h};
    auto val = [&](const Vec3& p) { return brute_trilinear(f, p, [](const Sample& s) { return double(s.value); }); };
    EXPECT_NEAR(g.x, (val(x + hx) - val(x - hx)) / (2 * h), 1e-3 * (1 + std::abs(g.x))) << k;
    EXPECT_NEAR(g.z, (val(x + hz) - val(x - hz)) / (2 * h), 1e-3 * (1 + std::abs(g.z))) << k;
  }
}

TEST(FieldView, NaNBackgroundIsOutsideEveryIsosurfaceAndEmptyFieldsReadNaN) {
  SampleField f = random_field({4, 4, 4}, std::numeric_limits<float>::quiet_NaN(), 5);
  for (Sample& s : f.samples) s.value = 100.0f;  // everything in the data is "inside" tau = 0
  const FieldView v(f);
  const Vec3 in = f.grid.to_world({1.5, 1.5, 1.5}), just_out = f.grid.to_world({3.2, 1.5, 1.5});
  for (InsideIs side : {InsideIs::kAbove, InsideIs::kBelow}) {
    const Isosurface iso{0.0, side};
    EXPECT_EQ(iso.contains(v.value(in)), side == InsideIs::kAbove);
    EXPECT_FALSE(iso.contains(v.value(just_out)));  // NaN: outside, whichever side is inside
  }
  EXPECT_TRUE(std::isnan(FieldView(SampleField{}).value({0, 0, 0})));
  SampleField short_field = f;
  short_field.samples.pop_back();  // fewer samples than voxels: an empty view, never a bad read
  EXPECT_TRUE(FieldView(short_field).empty());
  EXPECT_TRUE(std::isnan(FieldView(short_field).value(in)));
}

TEST(Isosurface, OneSignRuleForBothSides) {
  const Isosurface above{10.0, InsideIs::kAbove}, below{10.0, InsideIs::kBelow};
  EXPECT_EQ(above.excess(12.5), 2.5);
  EXPECT_EQ(below.excess(12.5), -2.5);
  EXPECT_FALSE(above.contains(10.0));  // the surface itself is outside
  EXPECT_FALSE(below.contains(10.0));
  EXPECT_EQ(above.excess(std::nan("")), -1.0);
  EXPECT_EQ(below.excess(std::nan("")), -1.0);
  const Vec3 g{1, -2, 3};
  EXPECT_EQ(above.outward(g).y, 2.0);   // density rises inward: outward is -grad
  EXPECT_EQ(below.outward(g).y, -2.0);  // distance rises outward: outward is +grad
  EXPECT_EQ(above.outside_value(-1000, 3000), -1000);
  EXPECT_EQ(above.outside_value(50, 3000), 10.0);  // nothing in the data is outside: tau
  EXPECT_EQ(below.outside_value(-5, 8), 10.0);
  EXPECT_EQ(below.outside_value(-5, 80), 80);
  SampleField f = random_field({3, 3, 3}, 0.0f, 6);
  f.samples[4].value = -std::numeric_limits<float>::infinity();
  f.samples[5].value = std::numeric_limits<float>::quiet_NaN();
  float lo = 1e30f;
  for (std::size_t i = 0; i < f.samples.size(); ++i)
    if (i != 4 && i != 5) lo = std::min(lo, f.samples[i].value);
  EXPECT_EQ(core::outside_background(f, {1000.0, InsideIs::kAbove}), lo);  // Inf and NaN skipped
}

// The renderers read through FieldView: a SampleField and its view give the same ticks,
// and a HIP that leaves the volume (default NaN background) leaves the object: no force.
TEST(FieldView, RenderersSeeTheSameFieldThroughTheViewAndNothingOutside) {
  SampleField f;
  f.grid.dims = {16, 16, 16};
  f.samples.resize(f.grid.voxel_count());
  for (int z = 0; z < 16; ++z)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) f.samples[f.grid.index(x, y, z)] = {float(1000 * (8e-3 - z * 1e-3)), 0, 0, -1000.0f};
  servo::HriParams p;
  p.tau = 0;
  servo::HriRenderer a(p), b(p);
  const FieldView v(f);
  long contact = 0;
  for (int k = 0; k < 400; ++k) {
    const Vec3 hip{7.5e-3, 7.5e-3, 10e-3 - 4e-3 * std::sin(k * 0.02)};  // presses 2 mm into z < 8 mm
    const servo::HriTick ta = a.tick(f, hip), tb = b.tick(v, hip);
    ASSERT_EQ(ta.force_n.z, tb.force_n.z) << k;
    contact += ta.contact;
  }
  EXPECT_GT(contact, 50);
  // Outside the grid in x (15.2 mm and beyond; the last voxel centre is at 15 mm), coming
  // down from 10 mm to 5.1 mm, through the depth that was in contact: nothing to touch
  // (clamp-to-edge would have given the border column's values, and contact).
  servo::HriRenderer c(p);
  for (int k = 0; k < 50; ++k) {
    const servo::HriTick t = c.tick(v, {0.0152 + 1e-4 * k, 7.5e-3, 10e-3 - 1e-4 * k});
    EXPECT_FALSE(t.contact);
    EXPECT_EQ(norm(t.force_n), 0.0);
  }
}

}  // namespace
}  // namespace isotouch
