// test_brick_field.cpp - the bricked snapshot against the dense one
// and against brute force written here from the contract in core/brick_field.h:
// - fp32 bricked reads are bit-identical to dense in every cell whose lower corner lies in
//   an active brick, and on the same side of the isosurface everywhere else in the grid;
// - the active set is the brute-force straddle test over each brick widened by 1 voxel;
// - compact formats stay within the error formulas of brick_field.h (every stored sample);
// - snapshot_bytes is the sum of the parts counted here;
// - HRI on a sphere gives the same forces on dense and bricked fp32 (within a stated
//   tolerance on fp16 / unorm16).
// Fields are analytic (sphere SDF, plane) or random (seeded), with dims that are not
// multiples of 8, a 1-voxel axis, and NaN or finite backgrounds.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <random>
#include <stdexcept>

#include "isotouch/core/brick_field.h"
#include "isotouch/core/field_view.h"
#include "isotouch/servo/hri.h"
#include "field_builders.h"

namespace isotouch {
namespace {
using core::BrickedInput;
using core::FieldView;
using core::InsideIs;
using core::Isosurface;
using core::Sample;
using core::SampleField;
using core::SampleFormat;
using core::Vec3;

constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();

// A dense field from value(p) and gradient(p) at the voxel centres (grid-world [m]).
SampleField analytic(std::array<int, 3> dims, Vec3 spacing, Vec3 origin, float background,
                     const std::function<double(const Vec3&)>& value, const std::function<Vec3(const Vec3&)>& grad) {
  SampleField f = test::sample_analytic(dims, spacing, origin, value, grad);
  f.background = background;
  return f;
}

// Sphere SDF [m], positive inside (kAbove, tau 0): R - |p - c|.
SampleField sphere(std::array<int, 3> dims, Vec3 spacing, Vec3 c, double r, float background) {
  return analytic(
      dims, spacing, {0, 0, 0}, background, [=](const Vec3& p) { return r - norm(p - c); },
      [=](const Vec3& p) {
        const double d = norm(p - c);
        return d > 0 ? (c - p) / d : Vec3{};
      });
}

// A tilted plane in HU-like units: 1000 * n.(p - c) / 1 mm.
SampleField plane(std::array<int, 3> dims, float background) {
  const Vec3 n = Vec3{0.3, -0.5, 0.81} / norm(Vec3{0.3, -0.5, 0.81});
  const Vec3 c{0.011, 0.009, 0.004};
  return analytic(
      dims, {1e-3, 1e-3, 1e-3}, {0, 0, 0}, background, [=](const Vec3& p) { return 1e6 * dot(n, p - c); },
      [=](const Vec3&) { return n * 1e6; });
}

// CT-like: a smooth blob (air -1000 HU outside, tissue ~ +300 inside), seeded noise of
// +-60 HU on the values and the gradients, a few NaN voxels.
SampleField noisy_ct(std::array<int, 3> dims, unsigned seed, float background) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Vec3 sp{0.7e-3, 0.8e-3, 1.25e-3}, origin{-0.01, 0.02, 0.005};
  const Vec3 c = origin + Vec3{sp.x * (dims[0] - 1), sp.y * (dims[1] - 1), sp.z * (dims[2] - 1)} * 0.45;
  SampleField f = analytic(
      dims, sp, origin, background,
      [&](const Vec3& p) {
        const double r2 = dot(p - c, p - c) / (0.009 * 0.009);
        return -1000.0 + 1400.0 * std::exp(-r2) + 60.0 * u(rng);
      },
      [&](const Vec3&) { return Vec3{2e5 * u(rng), 2e5 * u(rng), 2e5 * u(rng)}; });
  for (int k = 0; k < 5; ++k)
    f.samples[std::size_t(std::uniform_int_distribution<std::size_t>(0, f.samples.size() - 1)(rng))].value = kNaNf;
  return f;
}

struct Case {
  const char* name;
  SampleField dense;
  Isosurface iso;
};

std::vector<Case> cases() {
  std::vector<Case> c;
  c.push_back({"sphere NaN bg", sphere({37, 29, 43}, {1e-3, 1.2e-3, 0.9e-3}, {0.018, 0.017, 0.02}, 0.012, kNaNf),
               {0.0, InsideIs::kAbove}});
  c.push_back({"sphere finite bg", sphere({24, 24, 24}, {1e-3, 1e-3, 1e-3}, {0.0115, 0.0115, 0.0115}, 0.008, -0.02f),
               {0.0, InsideIs::kAbove}});
  // A NaN voxel at the centre of a brick that is otherwise entirely inside: the brick must
  // be active (dense reads NaN, outside, there; a tile would read inside).
  SampleField holed = sphere({40, 40, 40}, {1e-3, 1e-3, 1e-3}, {0.0195, 0.0195, 0.0195}, 0.014, -0.02f);
  holed.samples[holed.grid.index(19, 20, 19)].value = kNaNf;
  c.push_back({"sphere NaN voxel", std::move(holed), {0.0, InsideIs::kAbove}});
  c.push_back({"plane kBelow", plane({26, 17, 9}, kNaNf), {-300.0, InsideIs::kBelow}});
  c.push_back({"noisy CT", noisy_ct({33, 40, 21}, 7, kNaNf), {250.0, InsideIs::kAbove}});
  c.push_back({"noisy CT -500", noisy_ct({33, 40, 21}, 8, -1000.f), {-500.0, InsideIs::kAbove}});
  c.push_back({"thin (1-voxel z)", noisy_ct({40, 30, 1}, 9, kNaNf), {-200.0, InsideIs::kAbove}});
  return c;
}

bool same_bits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b) || (std::isnan(a) && std::isnan(b));
}

// The brute-force straddle test of brick (bx, by, bz): its voxels widened by 1 on every
// side, clipped to the grid, hold a voxel inside `iso` and one outside (NaN is outside).
bool straddles(const SampleField& f, const Isosurface& iso, int bx, int by, int bz) {
  bool in = false, out = false;
  const auto& d = f.grid.dims;
  for (int z = 8 * bz - 1; z <= 8 * bz + 8; ++z)
    for (int y = 8 * by - 1; y <= 8 * by + 8; ++y)
      for (int x = 8 * bx - 1; x <= 8 * bx + 8; ++x) {
        if (x < 0 || y < 0 || z < 0 || x >= d[0] || y >= d[1] || z >= d[2]) continue;
        const float v = f.samples[f.grid.index(x, y, z)].value;
        if (v != v) {
          out = true;
          continue;
        }
        (iso.contains(v) ? in : out) = true;
      }
  return in && out;
}

int nb(int n) { return (n + 7) / 8; }
std::size_t brick_id(const SampleField& f, int x, int y, int z) {
  return (std::size_t(z / 8) * std::size_t(nb(f.grid.dims[1])) + std::size_t(y / 8)) * std::size_t(nb(f.grid.dims[0])) +
         std::size_t(x / 8);
}

// The brick-active map, brute force.
std::vector<bool> brute_active(const SampleField& f, const Isosurface& iso) {
  std::vector<bool> a;
  for (int bz = 0; bz < nb(f.grid.dims[2]); ++bz)
    for (int by = 0; by < nb(f.grid.dims[1]); ++by)
      for (int bx = 0; bx < nb(f.grid.dims[0]); ++bx) a.push_back(straddles(f, iso, bx, by, bz));
  return a;
}

// Lower corner of the in-grid cell holding index coordinate v on an axis of n voxels.
int lower_corner(double v, int n) { return n > 1 ? std::min(int(std::floor(v)), n - 2) : 0; }

TEST(BrickField, ActiveSetIsTheBruteForceStraddleTestAndTilesKeepTheSide) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
    const std::vector<bool> want = brute_active(c.dense, c.iso);
    std::vector<bool> got(want.size(), false);
    for (std::uint32_t id : in.active) got[id] = true;
    EXPECT_EQ(got, want);
    std::size_t n_active = 0;
    for (bool b : want) n_active += b;
    EXPECT_GT(n_active, 0u);
    EXPECT_LT(n_active, want.size());
    // Every voxel of a uniform brick's widened range is on the tile's side.
    const auto& d = c.dense.grid.dims;
    for (int z = 0; z < d[2]; ++z)
      for (int y = 0; y < d[1]; ++y)
        for (int x = 0; x < d[0]; ++x)
          for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) {
                // voxel (x, y, z) lies in the widened range of the brick of (x+dx, y+dy, z+dz)
                const int ox = x + dx, oy = y + dy, oz = z + dz;
                if (ox < 0 || oy < 0 || oz < 0 || ox >= d[0] || oy >= d[1] || oz >= d[2]) continue;
                const std::size_t id = brick_id(c.dense, ox, oy, oz);
                if (want[id]) continue;
                const float v = c.dense.samples[c.dense.grid.index(x, y, z)].value;
                ASSERT_EQ(c.iso.contains(v), c.iso.contains(in.tile[id])) << x << " " << y << " " << z;
              }
  }
}

// fp32: bit-identical where the cell's brick is active, same side elsewhere in the grid,
// identical in the border band where every in-grid corner's brick is active.
TEST(BrickField, Fp32ReadsAreBitIdenticalInActiveCellsAndOnTheSameSideElsewhere) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const SampleField bricked = core::make_bricked_field(core::bricked_input_from_dense(c.dense, c.iso), SampleFormat::kFp32);
    ASSERT_TRUE(bricked.samples.empty());
    ASSERT_TRUE(bricked.bricked());
    EXPECT_EQ(bricked.version, 0u);
    EXPECT_TRUE(same_bits(bricked.background, c.dense.background));
    const FieldView dv(c.dense), bv(bricked);
    ASSERT_TRUE(bv.bricked());
    ASSERT_FALSE(dv.bricked());
    const std::vector<bool> active = brute_active(c.dense, c.iso);
    const auto& d = c.dense.grid.dims;
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    auto frac = [&] {  // cell fractions with the faces 0 and 1 exact now and then
      const double r = u01(rng);
      return r < 0.05 ? 0.0 : (r < 0.1 ? 1.0 : u01(rng));
    };
    // The point world(idx); the cell and bricks FieldView uses come from to_index(world),
    // which can differ from idx by an ulp (a point on a brick face may fall in either).
    // Identical expected where the in-grid cell's brick is active, or, in the border band,
    // where every in-grid corner's brick is; the same side anywhere else in the grid.
    auto compare = [&](const Vec3& idx_wanted) {
      const Vec3 w = c.dense.grid.to_world(idx_wanted);
      const Vec3 idx = c.dense.grid.to_index(w);
      const bool in_grid = idx.x >= 0 && idx.y >= 0 && idx.z >= 0 && idx.x <= d[0] - 1 && idx.y <= d[1] - 1 &&
                           idx.z <= d[2] - 1;
      bool expect_identical = true;
      if (in_grid) {
        expect_identical =
            active[brick_id(c.dense, lower_corner(idx.x, d[0]), lower_corner(idx.y, d[1]), lower_corner(idx.z, d[2]))];
      } else {
        for (int cz = int(std::floor(idx.z)); cz <= int(std::floor(idx.z)) + 1; ++cz)
          for (int cy = int(std::floor(idx.y)); cy <= int(std::floor(idx.y)) + 1; ++cy)
            for (int cx = int(std::floor(idx.x)); cx <= int(std::floor(idx.x)) + 1; ++cx)
              if (cx >= 0 && cy >= 0 && cz >= 0 && cx < d[0] && cy < d[1] && cz < d[2])
                expect_identical = expect_identical && active[brick_id(c.dense, cx, cy, cz)];
        if (!expect_identical) return 0;  // the border band next to a uniform brick: not specified
      }
      const double a = dv.value(w), b = bv.value(w);
      if (!expect_identical) {
        EXPECT_EQ(c.iso.contains(a), c.iso.contains(b)) << idx.x << " " << idx.y << " " << idx.z;
        return 2;
      }
      EXPECT_TRUE(same_bits(a, b)) << idx.x << " " << idx.y << " " << idx.z << ": " << a << " vs " << b;
      const core::FieldValue fa = dv.value_gradient(w), fb = bv.value_gradient(w);
      EXPECT_TRUE(same_bits(fa.value, fb.value) && same_bits(fa.gradient.x, fb.gradient.x) &&
                  same_bits(fa.gradient.y, fb.gradient.y) && same_bits(fa.gradient.z, fb.gradient.z))
          << idx.x << " " << idx.y << " " << idx.z;
      const Vec3 ga = dv.trilinear_gradient(w), gb = bv.trilinear_gradient(w);
      EXPECT_TRUE(same_bits(ga.x, gb.x) && same_bits(ga.y, gb.y) && same_bits(ga.z, gb.z))
          << idx.x << " " << idx.y << " " << idx.z;
      return in_grid ? 1 : 3;
    };
    // 1. Every active brick: random points in each of its cells (lower corner in the brick).
    long identical = 0;
    for (int bz = 0; bz < nb(d[2]); ++bz)
      for (int by = 0; by < nb(d[1]); ++by)
        for (int bx = 0; bx < nb(d[0]); ++bx) {
          if (!active[brick_id(c.dense, 8 * bx, 8 * by, 8 * bz)]) continue;
          const int b[3] = {bx, by, bz};
          int hi[3];
          for (int a = 0; a < 3; ++a) hi[a] = d[a] > 1 ? std::min(8 * b[a] + 7, d[a] - 2) : 0;
          for (int z = 8 * bz; z <= hi[2]; ++z)
            for (int y = 8 * by; y <= hi[1]; ++y)
              for (int x = 8 * bx; x <= hi[0]; ++x)
                for (int k = 0; k < 2; ++k) {
                  const Vec3 idx{x + (d[0] > 1 ? frac() : 0.0), y + (d[1] > 1 ? frac() : 0.0),
                                 z + (d[2] > 1 ? frac() : 0.0)};
                  identical += compare(idx) == 1;
                }
        }
    EXPECT_GT(identical, 1000);
    // 2. Anywhere in the grid.
    std::uniform_real_distribution<double> ux(0, d[0] - 1), uy(0, d[1] - 1), uz(0, d[2] - 1);
    long uniform_points = 0;
    for (int k = 0; k < 20000; ++k) uniform_points += compare({ux(rng), uy(rng), uz(rng)}) == 2;
    EXPECT_GT(uniform_points, 100);
    // 3. The border band and the grid edge: faces exactly, within 1e-9 voxel, up to 1.5
    // voxels out.
    const double edge[] = {-1.5, -1.0, -0.5, -1e-9, 0.0, 1e-9};
    long border = 0;
    for (int k = 0; k < 20000; ++k) {
      Vec3 idx;
      double* p[3] = {&idx.x, &idx.y, &idx.z};
      for (int a = 0; a < 3; ++a) {
        const double e = edge[std::uniform_int_distribution<int>(0, 5)(rng)];
        const int mode = std::uniform_int_distribution<int>(0, 2)(rng);
        *p[a] = mode == 0 ? e : (mode == 1 ? d[a] - 1 - e : u01(rng) * (d[a] - 1));
      }
      border += compare(idx) == 3;
    }
    EXPECT_GT(border, 100);
  }
}

// The brick of the cell of index coordinate v on an axis of n voxels (in the grid).
int cell_brick(double v, int n) { return lower_corner(v, n) / 8; }

// central_difference on a bricked fp32 field is, bit for bit, the six values value_at_index
// reads on the same view (its definition, whatever path computes it: the six cells in one
// active brick, in one uniform brick, or spread over two bricks), and the dense field's
// where every cell of the six points lies in an active brick. Points are drawn anywhere in
// the grid and, half of them, with a pair of points on either side of a brick face.
TEST(BrickField, Fp32CentralDifferenceIsTheSixBrickedValuesAndDenseInActiveBricks) {
  long one_active = 0, one_uniform = 0, spread = 0;
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const SampleField bricked = core::make_bricked_field(core::bricked_input_from_dense(c.dense, c.iso), SampleFormat::kFp32);
    const FieldView dv(c.dense), bv(bricked);
    const std::vector<bool> active = brute_active(c.dense, c.iso);
    const auto& d = c.dense.grid.dims;
    const Vec3 sp = c.dense.grid.spacing_m;
    std::mt19937 rng(21);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    for (int k = 0; k < 20000; ++k) {
      const double hv = k % 5 == 4 ? 0.3 : 0.5;  // the renderers' half voxel, and another step
      Vec3 idx;
      for (int a = 0; a < 3; ++a) {
        double v = u01(rng) * (d[a] - 1);
        // Half the points: the lower point of this axis's pair in the last cell of a brick
        // (voxel 8 m + 7), its upper point in the next brick.
        if (k % 2 == 0 && d[a] > 17 && u01(rng) < 0.6) v = 8.0 * std::floor(u01(rng) * ((d[a] - 10) / 8)) + 7 + hv + u01(rng);
        (&idx.x)[a] = v;
      }
      const Vec3 w = c.dense.grid.to_world(idx);
      const Vec3 h = sp * hv;
      const Vec3 i = c.dense.grid.to_index(w);
      const Vec3 hi{h.x / sp.x, h.y / sp.y, h.z / sp.z};
      const Vec3 pts[6] = {{i.x - hi.x, i.y, i.z}, {i.x + hi.x, i.y, i.z}, {i.x, i.y - hi.y, i.z},
                           {i.x, i.y + hi.y, i.z}, {i.x, i.y, i.z - hi.z}, {i.x, i.y, i.z + hi.z}};
      const Vec3 g = bv.central_difference(w, h);
      const Vec3 want{(bv.value_at_index(pts[1]) - bv.value_at_index(pts[0])) / (2 * h.x),
                      (bv.value_at_index(pts[3]) - bv.value_at_index(pts[2])) / (2 * h.y),
                      (bv.value_at_index(pts[5]) - bv.value_at_index(pts[4])) / (2 * h.z)};
      ASSERT_TRUE(same_bits(g.x, want.x) && same_bits(g.y, want.y) && same_bits(g.z, want.z))
          << k << " at " << i.x << " " << i.y << " " << i.z << ": (" << g.x << ", " << g.y << ", " << g.z << ") vs ("
          << want.x << ", " << want.y << ", " << want.z << ")";
      // Which bricks the six points' cells lie in (points in the grid only).
      bool in_grid = true, all_active = true, one_brick = true;
      std::size_t first = 0;
      for (int p = 0; p < 6; ++p) {
        const Vec3& q = pts[p];
        if (!(q.x >= 0 && q.y >= 0 && q.z >= 0 && q.x <= d[0] - 1 && q.y <= d[1] - 1 && q.z <= d[2] - 1)) {
          in_grid = false;
          break;
        }
        const std::size_t b = brick_id(c.dense, 8 * cell_brick(q.x, d[0]), 8 * cell_brick(q.y, d[1]), 8 * cell_brick(q.z, d[2]));
        all_active = all_active && active[b];
        if (p == 0) first = b;
        one_brick = one_brick && b == first;
      }
      if (!in_grid) continue;
      if (all_active) {
        const Vec3 gd = dv.central_difference(w, h);
        ASSERT_TRUE(same_bits(g.x, gd.x) && same_bits(g.y, gd.y) && same_bits(g.z, gd.z))
            << k << " at " << i.x << " " << i.y << " " << i.z;
      }
      one_active += one_brick && all_active;
      one_uniform += one_brick && !all_active;
      spread += !one_brick;
    }
  }
  // Every way of reading the six cells was exercised.
  EXPECT_GT(one_active, 2000);
  EXPECT_GT(one_uniform, 2000);
  EXPECT_GT(spread, 2000);
}

// A cell of a uniform brick reads the brick's tile at its 8 corners, so its trilinear
// value is the tile (the tiles here are finite and not zero: no lerp changes them).
TEST(BrickField, Fp32UniformCellsReadTheirTile) {
  long checked = 0;
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const SampleField bricked = core::make_bricked_field(core::bricked_input_from_dense(c.dense, c.iso), SampleFormat::kFp32);
    const FieldView bv(bricked);
    const core::BrickStore& store = *bricked.bricks;
    const auto& d = c.dense.grid.dims;
    std::mt19937 rng(23);
    std::uniform_real_distribution<double> ux(0, d[0] - 1), uy(0, d[1] - 1), uz(0, d[2] - 1);
    for (int k = 0; k < 20000; ++k) {
      const Vec3 w = c.dense.grid.to_world({ux(rng), uy(rng), uz(rng)});
      const Vec3 i = c.dense.grid.to_index(w);
      if (!(i.x >= 0 && i.y >= 0 && i.z >= 0 && i.x <= d[0] - 1 && i.y <= d[1] - 1 && i.z <= d[2] - 1)) continue;
      const std::uint32_t e = store.table[brick_id(c.dense, lower_corner(i.x, d[0]), lower_corner(i.y, d[1]), lower_corner(i.z, d[2]))];
      if (!(e & core::BrickStore::kUniform)) continue;
      const float tile = store.tiles[e & ~core::BrickStore::kUniform].value;
      if (!std::isfinite(tile) || tile == 0.0f) continue;
      ASSERT_EQ(bv.value(w), double(tile)) << k << " at " << i.x << " " << i.y << " " << i.z;
      ASSERT_EQ(bv.value_at_index(i), double(tile));
      ++checked;
    }
  }
  EXPECT_GT(checked, 10000);
}

TEST(BrickField, HalfCodecRoundTripsEveryHalfAndRoundsToNearest) {
  for (std::uint32_t h = 0; h < 0x10000u; ++h) {
    const float f = core::half_to_float(std::uint16_t(h));
    if (std::isnan(f)) {
      ASSERT_EQ(h & 0x7c00u, 0x7c00u) << h;
      ASSERT_NE(h & 0x3ffu, 0u) << h;
      continue;
    }
    ASSERT_EQ(core::float_to_half(f), h) << h;
  }
  // Definition of binary16: 1.0 = 0x3c00, 65504 = 0x7bff, 2^-24 = 0x0001, -2 = 0xc000.
  EXPECT_EQ(core::half_to_float(0x3c00), 1.0f);
  EXPECT_EQ(core::half_to_float(0x7bff), 65504.0f);
  EXPECT_EQ(core::half_to_float(0x0001), 0x1p-24f);
  EXPECT_EQ(core::half_to_float(0xc000), -2.0f);
  EXPECT_EQ(core::float_to_half(1e9), 0x7bffu);  // saturates
  // Nearest: no neighbour half is nearer; the bound of brick_field.h holds.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> e(-30.0, 16.0), s(1.0, 2.0);
  for (int k = 0; k < 200000; ++k) {
    const double x = (k & 1 ? -1 : 1) * s(rng) * std::exp2(std::floor(e(rng)));
    if (std::abs(x) >= 65504) continue;
    const std::uint16_t h = core::float_to_half(x);
    const double d = std::abs(double(core::half_to_float(h)) - x);
    ASSERT_LE(d, 0x1p-11 * std::abs(x) + 0x1p-25) << x;
    for (int n : {-1, 1}) {
      const std::uint16_t hn = std::uint16_t(h + n);
      if ((hn & 0x7c00u) == 0x7c00u || ((hn ^ h) & 0x8000u)) continue;
      ASSERT_LE(d, std::abs(double(core::half_to_float(hn)) - x)) << x;
    }
  }
}

// Every stored sample inside the grid decodes within the formulas of brick_field.h,
// with lo, hi computed here from the dense samples.
TEST(BrickField, CompactFormatsStayWithinTheDocumentedBound) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
    const SampleField f16 = core::make_bricked_field(in, SampleFormat::kFp16);
    const SampleField u16 = core::make_bricked_field(in, SampleFormat::kUnorm16);
    const auto& d = c.dense.grid.dims;
    const double sp[3] = {c.dense.grid.spacing_m.x, c.dense.grid.spacing_m.y, c.dense.grid.spacing_m.z};
    double worst16[4] = {0, 0, 0, 0}, worstu[4] = {0, 0, 0, 0};  // error / bound
    double max16[4] = {0, 0, 0, 0}, maxu[4] = {0, 0, 0, 0};        // absolute error
    for (std::size_t slot = 0; slot < in.active.size(); ++slot) {
      const std::size_t id = in.active[slot];
      const int bx = int(id % std::size_t(nb(d[0]))), by = int(id / std::size_t(nb(d[0])) % std::size_t(nb(d[1]))),
                bz = int(id / std::size_t(nb(d[0]) * nb(d[1])));
      std::vector<std::array<int, 3>> voxels;
      for (int k = 0; k < 9; ++k)
        for (int j = 0; j < 9; ++j)
          for (int i = 0; i < 9; ++i)
            if (8 * bx + i < d[0] && 8 * by + j < d[1] && 8 * bz + k < d[2]) voxels.push_back({i, j, k});
      auto chan = [&](const std::array<int, 3>& l, int ch) {
        const Sample& s = c.dense.samples[c.dense.grid.index(8 * bx + l[0], 8 * by + l[1], 8 * bz + l[2])];
        return double(ch == 0 ? s.value : (ch == 1 ? s.gx : (ch == 2 ? s.gy : s.gz)));
      };
      for (int ch = 0; ch < 4; ++ch) {
        double lo = INFINITY, hi = -INFINITY;
        for (const auto& l : voxels)
          if (std::isfinite(chan(l, ch))) lo = std::min(lo, chan(l, ch)), hi = std::max(hi, chan(l, ch));
        for (const auto& l : voxels) {
          const double x = chan(l, ch);
          const std::size_t local = std::size_t(l[0] + 9 * l[1] + 81 * l[2]);
          const Sample a = f16.bricks->stored(std::uint32_t(slot), local);
          const Sample b = u16.bricks->stored(std::uint32_t(slot), local);
          const double xa = ch == 0 ? a.value : (ch == 1 ? a.gx : (ch == 2 ? a.gy : a.gz));
          const double xb = ch == 0 ? b.value : (ch == 1 ? b.gx : (ch == 2 ? b.gy : b.gz));
          if (!std::isfinite(x)) {
            ASSERT_TRUE(std::isnan(xb));
            ASSERT_TRUE(same_bits(xa, x) || (std::isnan(xa) && std::isnan(x)));
            continue;
          }
          const double s = ch == 0 ? 1.0 : sp[ch - 1];
          const double b16 = ch == 0 ? 0x1p-11 * std::abs(x) + 0x1p-25
                                     : (0x1p-11 + 0x1p-22) * std::abs(x) + 0x1p-24 / s;
          const double bu = 0.5 * (hi - lo) / 65534.0 * (1 + 0x1p-22) + 0x1p-22 * std::max(std::abs(lo), std::abs(hi));
          ASSERT_LE(std::abs(xa - x), b16) << "fp16 channel " << ch << " x " << x;
          ASSERT_LE(std::abs(xb - x), bu) << "unorm16 channel " << ch << " x " << x << " range " << lo << " " << hi;
          worst16[ch] = std::max(worst16[ch], std::abs(xa - x) / b16);
          worstu[ch] = std::max(worstu[ch], std::abs(xb - x) / bu);
          max16[ch] = std::max(max16[ch], std::abs(xa - x));
          maxu[ch] = std::max(maxu[ch], std::abs(xb - x));
        }
      }
    }
    std::printf("%-18s max |error| value, gx, gy, gz: fp16 %.3g %.3g %.3g %.3g (%.2f of bound), unorm16 %.3g %.3g "
                "%.3g %.3g (%.2f of bound)\n",
                c.name, max16[0], max16[1], max16[2], max16[3],
                std::max({worst16[0], worst16[1], worst16[2], worst16[3]}), maxu[0], maxu[1], maxu[2], maxu[3],
                std::max({worstu[0], worstu[1], worstu[2], worstu[3]}));
    // The compact view: a cell reads the decoded corners, so its value is within the
    // largest corner error of dense (plus the interpolation's own rounding).
    const FieldView dv(c.dense), v16(f16), vu(u16);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> ux(0, d[0] - 1), uy(0, d[1] - 1), uz(0, d[2] - 1);
    for (int k = 0; k < 5000; ++k) {
      const Vec3 idx{ux(rng), uy(rng), uz(rng)};
      const std::size_t id =
          brick_id(c.dense, lower_corner(idx.x, d[0]), lower_corner(idx.y, d[1]), lower_corner(idx.z, d[2]));
      if (std::find(in.active.begin(), in.active.end(), std::uint32_t(id)) == in.active.end()) {
        const Vec3 w = c.dense.grid.to_world(idx);
        ASSERT_TRUE(same_bits(v16.value(w), FieldView(core::make_bricked_field(in, SampleFormat::kFp32)).value(w)));
        continue;
      }
      double corner_err = 0;
      for (int cz = 0; cz < 2; ++cz)
        for (int cy = 0; cy < 2; ++cy)
          for (int cx = 0; cx < 2; ++cx) {
            const int x = std::min(lower_corner(idx.x, d[0]) + cx, d[0] - 1),
                      y = std::min(lower_corner(idx.y, d[1]) + cy, d[1] - 1),
                      z = std::min(lower_corner(idx.z, d[2]) + cz, d[2] - 1);
            const double v = c.dense.samples[c.dense.grid.index(x, y, z)].value;
            corner_err = std::max(corner_err, std::abs(double(FieldView(u16).voxel(x, y, z).value) - v));
            corner_err = std::max(corner_err, std::abs(double(FieldView(f16).voxel(x, y, z).value) - v));
          }
      const Vec3 w = c.dense.grid.to_world(idx);
      const double ref = dv.value(w);
      if (std::isnan(ref)) continue;
      const double tol = corner_err + 1e-12 * (1 + std::abs(ref));
      ASSERT_NEAR(v16.value(w), ref, tol) << k;
      ASSERT_NEAR(vu.value(w), ref, tol) << k;
      ASSERT_NEAR(v16.value_gradient(w).value, ref, tol) << k;
    }
  }
}

TEST(BrickField, SnapshotBytesIsTheSumOfItsParts) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const std::vector<bool> act = brute_active(c.dense, c.iso);
    std::uint64_t total = act.size(), active = 0;
    for (bool b : act) active += b;
    const BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
    EXPECT_EQ(core::snapshot_bytes(c.dense), std::uint64_t(c.dense.samples.size()) * 16u);
    const std::uint64_t common = 4 * total + 16 * (total - active);
    EXPECT_EQ(core::snapshot_bytes(core::make_bricked_field(in, SampleFormat::kFp32)), common + active * 729 * 16);
    EXPECT_EQ(core::snapshot_bytes(core::make_bricked_field(in, SampleFormat::kFp16)), common + active * 729 * 8);
    EXPECT_EQ(core::snapshot_bytes(core::make_bricked_field(in, SampleFormat::kUnorm16)),
              common + active * 729 * 8 + active * 32);
    const core::BrickUsage use = core::brick_usage(core::make_bricked_field(in, SampleFormat::kFp16));
    EXPECT_EQ(use.total, total);
    EXPECT_EQ(use.active, active);
  }
}

TEST(BrickField, OutsideBackgroundOnABrickedFieldIsOutsideAndNoFartherThanDense) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
    for (SampleFormat fmt : {SampleFormat::kFp32, SampleFormat::kFp16, SampleFormat::kUnorm16}) {
      const float dense_bg = core::outside_background(c.dense, c.iso);
      const float bg = core::outside_background(core::make_bricked_field(in, fmt), c.iso);
      EXPECT_FALSE(c.iso.contains(bg));
      ASSERT_TRUE(std::isfinite(bg));
      // The stored values are (decoded) dense values: their range lies within dense's,
      // so the outside value is no farther from tau (compact: up to the quantisation).
      const double slack = fmt == SampleFormat::kFp32 ? 0.0 : 1e-3 * (1 + std::abs(dense_bg));
      if (c.iso.inside == InsideIs::kAbove) {
        EXPECT_GE(bg, dense_bg - slack);
      } else {
        EXPECT_LE(bg, dense_bg + slack);
      }
    }
  }
}

// The contract: stored positions beyond the grid hold {background, 0, 0, 0}, whatever
// the engine wrote there (they are never read; the fill keeps the pool well defined).
TEST(BrickField, TheApronBeyondTheGridIsTheBackground) {
  const Case c = cases()[0];  // 37 x 29 x 43: every axis ends inside a brick
  BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
  for (Sample& s : in.pool) s = {1e30f, 1.f, 2.f, 3.f};  // junk everywhere, in the grid too
  const auto nb3 = core::brick_counts(c.dense.grid);
  const SampleField f = core::make_bricked_field(in, SampleFormat::kFp32);
  long beyond = 0;
  for (std::size_t slot = 0; slot < in.active.size(); ++slot) {
    const auto b = core::brick_coords(in.active[slot], nb3);
    for (int k = 0; k < 9; ++k)
      for (int j = 0; j < 9; ++j)
        for (int i = 0; i < 9; ++i) {
          const bool out = 8 * b[0] + i >= c.dense.grid.dims[0] || 8 * b[1] + j >= c.dense.grid.dims[1] ||
                           8 * b[2] + k >= c.dense.grid.dims[2];
          const Sample s = f.bricks->stored(std::uint32_t(slot), std::size_t(i + 9 * j + 81 * k));
          if (!out) continue;
          ++beyond;
          ASSERT_TRUE(std::isnan(s.value) && s.gx == 0 && s.gy == 0 && s.gz == 0);  // background NaN
        }
  }
  EXPECT_GT(beyond, 0);
}

// A PoolSink gets the fp32 pool's buffer (the very memory the store read) only when the
// last reference to the published field is gone; a compact format's once it is encoded;
// a sink destroyed first leaves the store to free it.
TEST(BrickField, ThePoolSinkGetsTheBufferOnlyWhenTheStoreDies) {
  struct Sink : core::PoolSink {
    std::vector<const Sample*> got;
    void give_back(core::SamplePool&& p) noexcept override {
      got.push_back(p.data());
      core::SamplePool gone = std::move(p);
    }
  };
  const Case c = cases()[0];
  auto sink = std::make_shared<Sink>();
  BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
  ASSERT_FALSE(in.active.empty());
  in.recycle = sink;
  auto f = std::make_shared<SampleField>(core::make_bricked_field(in, SampleFormat::kFp32));
  const Sample* pool = f->bricks->pool->data();
  std::shared_ptr<const core::BrickStore> held = f->bricks;  // a second holder (the servo's copy)
  EXPECT_TRUE(sink->got.empty()) << "handed back while the field is alive";
  f.reset();
  EXPECT_TRUE(sink->got.empty()) << "handed back while a store reference is held";
  EXPECT_EQ(held->stored(0, 0).value, in.pool[0].value) << "the held store still reads its samples";
  held.reset();
  ASSERT_EQ(sink->got.size(), 1u);
  EXPECT_EQ(sink->got[0], pool) << "the sink gets the buffer the store read";

  (void)core::make_bricked_field(in, SampleFormat::kFp16);  // encoded: the fp32 pool is not needed
  EXPECT_EQ(sink->got.size(), 2u) << "a compact format hands the fp32 pool back once encoded";

  SampleField orphan = core::make_bricked_field(in, SampleFormat::kFp32);
  sink.reset();  // the sink dies first: the store frees its buffer itself
  orphan = SampleField{};
}

TEST(BrickField, BadInputIsRefusedNamingTheField) {
  const Case c = cases()[1];
  BrickedInput in = core::bricked_input_from_dense(c.dense, c.iso);
  auto refused = [](BrickedInput b, const char* field) {
    try {
      (void)core::make_bricked_field(std::move(b), SampleFormat::kFp32);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what()).find(field) != std::string::npos;
    }
    return false;
  };
  BrickedInput b = in;
  b.tile.pop_back();
  EXPECT_TRUE(refused(b, "BrickedInput.tile"));
  b = in;
  b.pool.pop_back();
  EXPECT_TRUE(refused(b, "BrickedInput.pool"));
  b = in;
  std::swap(b.active[0], b.active[1]);
  EXPECT_TRUE(refused(b, "BrickedInput.active"));
  b = in;
  b.grid.dims = {0, 4, 4};
  EXPECT_TRUE(refused(b, "BrickedInput.grid"));
  EXPECT_THROW((void)core::bricked_input_from_dense(core::make_bricked_field(in, SampleFormat::kFp32), c.iso),
               std::invalid_argument);
  // A store that does not match its grid gives an empty view, never a bad read.
  SampleField f = core::make_bricked_field(in, SampleFormat::kFp32);
  f.grid.dims[0] += 8;
  EXPECT_TRUE(FieldView(f).empty());
  EXPECT_TRUE(std::isnan(FieldView(f).value(f.grid.centre_m())));
  // An unsealed store (built by hand), or one whose table is cut short, reads nothing.
  const SampleField good = core::make_bricked_field(in, SampleFormat::kFp32);
  auto copy = std::make_shared<core::BrickStore>();
  copy->bricks = good.bricks->bricks;
  copy->table = good.bricks->table;
  copy->tiles = good.bricks->tiles;
  copy->pool = good.bricks->pool;
  SampleField hand = good;
  hand.bricks = copy;
  EXPECT_TRUE(FieldView(hand).empty());
  EXPECT_TRUE(copy->seal(good.grid.dims));
  EXPECT_FALSE(FieldView(hand).empty());
  EXPECT_TRUE(same_bits(FieldView(hand).value(good.grid.centre_m()), FieldView(good).value(good.grid.centre_m())));
  copy->table.pop_back();
  EXPECT_FALSE(copy->seal(good.grid.dims));
  EXPECT_TRUE(FieldView(hand).empty());
  copy->table = good.bricks->table;
  copy->table[0] = 5;  // not a slot start
  EXPECT_FALSE(copy->seal(good.grid.dims));
  const std::uint32_t slots = std::uint32_t(good.bricks->active_bricks());
  ASSERT_GT(slots, 0u);
  copy->table = good.bricks->table;
  copy->table.back() = slots * std::uint32_t(core::kBrickSamples);  // a slot start past the last slot
  EXPECT_FALSE(copy->seal(good.grid.dims));
  copy->table.back() = (slots - 1) * std::uint32_t(core::kBrickSamples);  // the last slot: in range
  EXPECT_TRUE(copy->seal(good.grid.dims));
  ASSERT_FALSE(good.bricks->tiles.empty());
  copy->table = good.bricks->table;
  copy->table[copy->table.size() / 2] = core::BrickStore::kUniform | std::uint32_t(good.bricks->tiles.size());  // no such tile
  EXPECT_FALSE(copy->seal(good.grid.dims));
  copy->table[copy->table.size() / 2] = core::BrickStore::kUniform | std::uint32_t(good.bricks->tiles.size() - 1);
  EXPECT_TRUE(copy->seal(good.grid.dims));
  // Compact formats refuse what they would move across an isovalue: fp16 beyond 65504
  // (saturation), unorm16 +-Inf (no code); fp32 stores both.
  ASSERT_FALSE(in.pool.empty());
  b = in;
  b.pool[0].value = 70000.0f;
  EXPECT_THROW((void)core::make_bricked_field(b, SampleFormat::kFp16), std::invalid_argument);
  EXPECT_NO_THROW((void)core::make_bricked_field(b, SampleFormat::kUnorm16));
  b.pool[0].value = std::numeric_limits<float>::infinity();
  EXPECT_THROW((void)core::make_bricked_field(b, SampleFormat::kUnorm16), std::invalid_argument);
  EXPECT_NO_THROW((void)core::make_bricked_field(b, SampleFormat::kFp32));
}

// A scripted stroke over a sphere (down through the surface, slide, up): HIP per tick.
std::vector<Vec3> stroke(const Vec3& c, double r) {
  std::vector<Vec3> hip;
  const Vec3 top = c + Vec3{0, 0, r};
  for (int t = 0; t < 300; ++t) hip.push_back(top + Vec3{0, 0, 0.003 - 0.005 * t / 299.0});  // to 2 mm deep
  for (int t = 0; t < 400; ++t) hip.push_back(top + Vec3{0.004 * t / 399.0, 0.002 * t / 399.0, -0.002});
  for (int t = 0; t < 300; ++t) hip.push_back(top + Vec3{0.004, 0.002, -0.002 + 0.005 * t / 299.0});
  return hip;
}

std::vector<Vec3> forces(const servo::HriParams& p, const SampleField& f, const std::vector<Vec3>& hip) {
  servo::HriRenderer r(p);
  std::vector<Vec3> out;
  for (const Vec3& h : hip) out.push_back(r.tick(f, h).force_n);
  return out;
}

TEST(BrickField, HriForcesOnASphereAreIdenticalOnFp32AndCloseOnCompactBricks) {
  const Vec3 c{0.0201, 0.0196, 0.0203};
  const double r = 0.011;
  const SampleField dense = sphere({40, 40, 40}, {1e-3, 1e-3, 1e-3}, c, r, -0.02f);
  const Isosurface iso{0.0, InsideIs::kAbove};
  const BrickedInput in = core::bricked_input_from_dense(dense, iso);
  const std::vector<Vec3> hip = stroke(c, r);
  // The precondition of "identical": every HIP lies in a cell of an active brick.
  const std::vector<bool> act = brute_active(dense, iso);
  for (const Vec3& h : hip) {
    if (!iso.contains(FieldView(dense).value(h))) continue;  // free space: the side is what counts
    const Vec3 i = dense.grid.to_index(h);
    ASSERT_TRUE(act[brick_id(dense, lower_corner(i.x, 40), lower_corner(i.y, 40), lower_corner(i.z, 40))]);
  }
  servo::HriParams robust;
  robust.tau = 0;
  robust.stiffness_n_per_m = 400;
  robust.force_limit_n = 3.3;
  servo::HriParams paper = robust;
  paper.variant = servo::Variant::kPaper;
  paper.normal = servo::NormalSource::kCentral;
  servo::HriParams exact = robust;
  exact.intersection = servo::Intersection::kBisection;
  exact.normal = servo::NormalSource::kTrilinearExact;
  for (const servo::HriParams& p : {robust, paper, exact}) {
    const std::vector<Vec3> fd = forces(p, dense, hip);
    double peak = 0;
    for (const Vec3& f : fd) peak = std::max(peak, norm(f));
    ASSERT_GT(peak, 0.5);  // the stroke presses: 400 N/m * 2 mm = 0.8 N
    const std::vector<Vec3> f32 = forces(p, core::make_bricked_field(in, SampleFormat::kFp32), hip);
    for (std::size_t t = 0; t < hip.size(); ++t)
      ASSERT_TRUE(same_bits(fd[t].x, f32[t].x) && same_bits(fd[t].y, f32[t].y) && same_bits(fd[t].z, f32[t].z))
          << "tick " << t;
    // Compact: the SDF's values and gradients to ~1e-4 relative move the surface by
    // micrometres; stated tolerance 1 % of the peak force on every tick.
    for (SampleFormat fmt : {SampleFormat::kFp16, SampleFormat::kUnorm16}) {
      const std::vector<Vec3> fc = forces(p, core::make_bricked_field(in, fmt), hip);
      double worst = 0;
      for (std::size_t t = 0; t < hip.size(); ++t) worst = std::max(worst, norm(fc[t] - fd[t]));
      std::printf("HRI %s/%s on %s: max |F - F_dense| %.3g N (peak %.3g N)\n",
                  p.variant == servo::Variant::kPaper ? "paper" : "robust",
                  p.normal == servo::NormalSource::kTrilinearExact ? "trilinear" : "default", core::to_string(fmt), worst,
                  peak);
      EXPECT_LE(worst, 0.01 * peak) << core::to_string(fmt);
    }
  }
}

}  // namespace
}  // namespace isotouch

// copy_brick_voxels copies exactly the voxels of one brick's box clipped to the grid: on a
// grid whose sizes are no multiples of 8 (edge bricks of 5, 2 and 1 voxels) every brick,
// against a triple loop over the box written out here; every other voxel keeps its value.
TEST(BrickField, CopyBrickVoxelsCopiesExactlyTheBricksClippedBox) {
  isotouch::core::Grid g;
  g.dims = {13, 10, 9};
  std::vector<float> from(g.voxel_count());
  for (std::size_t i = 0; i < from.size(); ++i) from[i] = float(i) + 0.5f;
  const auto nb = isotouch::core::brick_counts(g);
  ASSERT_EQ(nb, (std::array<int, 3>{2, 2, 2}));
  for (std::size_t id = 0; id < 8; ++id) {
    std::vector<float> to(g.voxel_count(), -1.0f);
    isotouch::core::copy_brick_voxels(g, id, from.data(), to.data());
    const auto b = isotouch::core::brick_coords(id, nb);
    long copied = 0;
    for (int z = 0; z < g.dims[2]; ++z)
      for (int y = 0; y < g.dims[1]; ++y)
        for (int x = 0; x < g.dims[0]; ++x) {
          const bool in = x / 8 == b[0] && y / 8 == b[1] && z / 8 == b[2];
          const std::size_t i = g.index(x, y, z);
          ASSERT_EQ(to[i], in ? from[i] : -1.0f) << "brick " << id << " voxel " << x << "," << y << "," << z;
          copied += in;
        }
    const long want = long(std::min(8, 13 - 8 * b[0])) * std::min(8, 10 - 8 * b[1]) * std::min(8, 9 - 8 * b[2]);
    EXPECT_EQ(copied, want) << "brick " << id;
  }
}
