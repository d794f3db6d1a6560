// Sparse chain: the GPU sparse chain and its CPU reference against the
// dense CPU chain (run_chain_cpu: truth from outside the sparse code), the validation layer
// on (any message fails):
// - every stored sample (729 per active brick, inside the grid) is bit-identical to the
//   dense chain's sample at that voxel;
// - the active set equals brute force over the dense smoothed field (range over the brick
//   + 1 voxel straddles tau) and every uniform brick's tile is on the side of every voxel
//   of its brick + 1 voxel;
// - CPU sparse == GPU sparse bit for bit; forced small bindings (many slabs / pool chunks)
//   give the same result.
// Plus a disabled benchmark (chest CT, -500 and +250 HU): sparse GPU vs dense CPU.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include "vk_test_context.h"
#include "cpu_filters.h"
#include "isotouch_shared.h"
#include "passes.h"
#include "sparse_chain.h"
#include "synthetic.h"
#include "volume_io.h"

using namespace isotouch;
using engine::PassDesc;
using engine::Volume;

namespace {
const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kHead = kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
const std::string kChest = kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd";

engine::VulkanContext& vk() { return test::validated_vk(); }

core::Isosurface above(double tau) { return {tau, core::InsideIs::kAbove}; }

std::uint32_t bits(float f) { return std::bit_cast<std::uint32_t>(f); }
bool same(const core::Sample& a, const core::Sample& b) {
  return bits(a.value) == bits(b.value) && bits(a.gx) == bits(b.gx) && bits(a.gy) == bits(b.gy) &&
         bits(a.gz) == bits(b.gz);
}

using Strategy = engine::SparseChain::Strategy;
engine::SparseOutput run_gpu(const Volume& v, const std::vector<PassDesc>& passes, const core::Isosurface& iso,
                             float background, std::uint64_t max_binding = 0, std::uint32_t max_groups = 0,
                             Strategy strategy = Strategy::Lists) {
  auto chain = engine::SparseChain::create(vk(), passes);
  if (!chain) throw std::runtime_error(chain.error);
  (*chain.value)->set_strategy(strategy);
  (*chain.value)->set_keep_input(true);
  (*chain.value)->set_max_workgroups(max_groups);
  engine::SparseOutput out = (*chain.value)->run(v, iso, background, core::SampleFormat::kFp32, max_binding);
  std::printf("  %s\n", (*chain.value)->describe().c_str());
  return out;
}

// Dense CPU truth against one sparse result: samples, active set, tiles.
void expect_matches_dense(const Volume& v, const std::vector<PassDesc>& passes, const core::Isosurface& iso,
                          const engine::SparseOutput& s, const std::string& what, bool expect_surface = true) {
  const engine::ChainOutput dense = engine::run_chain_cpu(v, passes);
  ASSERT_TRUE(dense.samples) << what;
  const auto& d = dense.samples->samples;
  const core::Grid& g = v.grid;
  const auto nb = core::brick_counts(g);
  const std::size_t total = std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]);
  const core::BrickedInput& in = s.input;
  ASSERT_EQ(in.tile.size(), total) << what;
  ASSERT_EQ(in.pool.size(), in.active.size() * std::size_t(core::kBrickSamples)) << what;
  EXPECT_EQ(s.stats.bricks_total, total);
  EXPECT_EQ(s.stats.active, in.active.size());
  EXPECT_LE(s.stats.active, s.stats.candidates);
  std::vector<int> slot(total, -1);
  for (std::size_t i = 0; i < in.active.size(); ++i) slot[in.active[i]] = int(i);
  std::size_t brute_active = 0, compared = 0, wrong_samples = 0, wrong_side = 0;
  for (std::size_t id = 0; id < total; ++id) {
    const auto b = core::brick_coords(id, nb);
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::max(8 * b[std::size_t(a)] - 1, 0);
      hi[a] = std::min(8 * b[std::size_t(a)] + 9, g.dims[std::size_t(a)]);
    }
    float mn = std::numeric_limits<float>::infinity(), mx = -mn;
    for (int z = lo[2]; z < hi[2]; ++z)
      for (int y = lo[1]; y < hi[1]; ++y)
        for (int x = lo[0]; x < hi[0]; ++x) {
          const float f = d[g.index(x, y, z)].value;
          mn = f < mn ? f : mn;
          mx = f > mx ? f : mx;
        }
    // Brute force: straddles iff some voxel is inside and some is not (NaN-free data).
    bool any_in = false, any_out = false;
    for (int z = lo[2]; z < hi[2]; ++z)
      for (int y = lo[1]; y < hi[1]; ++y)
        for (int x = lo[0]; x < hi[0]; ++x) (iso.contains(d[g.index(x, y, z)].value) ? any_in : any_out) = true;
    const bool straddles = any_in && any_out;
    brute_active += straddles;
    EXPECT_EQ(slot[id] >= 0, straddles) << what << ": brick " << id << " range " << mn << ".." << mx;
    if (slot[id] < 0) {
      const bool inside = iso.contains(in.tile[id]);
      for (int z = lo[2]; z < hi[2]; ++z)
        for (int y = lo[1]; y < hi[1]; ++y)
          for (int x = lo[0]; x < hi[0]; ++x) wrong_side += iso.contains(d[g.index(x, y, z)].value) != inside;
      continue;
    }
    const core::Sample* p = in.pool.data() + std::size_t(slot[id]) * core::kBrickSamples;
    for (int k = 0; k < 9; ++k)
      for (int j = 0; j < 9; ++j)
        for (int i = 0; i < 9; ++i) {
          const int x = 8 * b[0] + i, y = 8 * b[1] + j, z = 8 * b[2] + k;
          if (x >= g.dims[0] || y >= g.dims[1] || z >= g.dims[2]) continue;
          ++compared;
          const core::Sample& got = p[i + 9 * j + 81 * k];
          const core::Sample& want = d[g.index(x, y, z)];
          if (!same(got, want) && wrong_samples++ < 5)
            ADD_FAILURE() << what << ": voxel " << x << "," << y << "," << z << " sparse {" << got.value << ", "
                          << got.gx << ", " << got.gy << ", " << got.gz << "} dense {" << want.value << ", " << want.gx
                          << ", " << want.gy << ", " << want.gz << "}";
        }
  }
  EXPECT_EQ(wrong_samples, 0u) << what;
  EXPECT_EQ(wrong_side, 0u) << what << ": voxels on the other side of their uniform brick's tile";
  if (expect_surface) {
    EXPECT_GT(brute_active, 0u) << what << ": the case must have a surface";
  }
  std::printf("  %-40s %zu bricks, %zu candidates, %zu active (brute force %zu), %zu samples bit-identical\n",
              what.c_str(), total, s.stats.candidates, s.stats.active, brute_active, compared - wrong_samples);
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

void expect_same_output(const engine::SparseOutput& a, const engine::SparseOutput& b, const std::string& what) {
  EXPECT_EQ(a.stats.candidates, b.stats.candidates) << what;
  ASSERT_EQ(a.input.active, b.input.active) << what;
  ASSERT_EQ(a.input.pool.size(), b.input.pool.size()) << what;
  std::size_t diff = 0;
  for (std::size_t i = 0; i < a.input.pool.size(); ++i) diff += !same(a.input.pool[i], b.input.pool[i]);
  EXPECT_EQ(diff, 0u) << what << ": pool samples differ";
  ASSERT_EQ(a.input.tile.size(), b.input.tile.size()) << what;
  std::size_t tdiff = 0;
  for (std::size_t i = 0; i < a.input.tile.size(); ++i)
    if (!std::binary_search(a.input.active.begin(), a.input.active.end(), std::uint32_t(i)))
      tdiff += bits(a.input.tile[i]) != bits(b.input.tile[i]);
  EXPECT_EQ(tdiff, 0u) << what << ": tiles differ";
}

const char* strategy_name(Strategy s) {
  return s == Strategy::Lists ? " [lists strategy]" : s == Strategy::Dense ? " [dense strategy]" : " [per-brick strategy]";
}

// GPU vs dense, CPU sparse vs GPU sparse, and small bindings vs default; every strategy
// (x4 passes on the candidates' work lists, dense x4 passes + host gather, the per-brick
// shared-memory kernel).
void check_case_with(Strategy strategy, const Volume& v, const std::vector<PassDesc>& passes,
                     const core::Isosurface& iso, float background, const std::string& what_in,
                     std::uint64_t small_binding) {
  const std::string what = what_in + strategy_name(strategy);
  const engine::SparseOutput gpu = run_gpu(v, passes, iso, background, 0, 0, strategy);
  expect_matches_dense(v, passes, iso, gpu, what + " (GPU)");
  const engine::SparseOutput cpu = engine::run_sparse_cpu(v, passes, iso, background, core::SampleFormat::kFp32, true);
  expect_same_output(gpu, cpu, what + ": GPU vs CPU sparse");
  if (small_binding) {
    const engine::SparseOutput small = run_gpu(v, passes, iso, background, small_binding, 0, strategy);
    expect_same_output(gpu, small, what + ": small bindings");
    EXPECT_GE(small.stats.slabs, 2u) << what << ": the small binding must force several slabs";
    EXPECT_GT(small.stats.dispatches, small.stats.slabs) << what << ": ... and several pool chunks";
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}
void check_case(const Volume& v, const std::vector<PassDesc>& passes, const core::Isosurface& iso, float background,
                const std::string& what, std::uint64_t small_binding = 0) {
  check_case_with(Strategy::Lists, v, passes, iso, background, what, small_binding);
  check_case_with(Strategy::Dense, v, passes, iso, background, what, small_binding);
  check_case_with(Strategy::PerBrick, v, passes, iso, background, what, small_binding);
}
}  // namespace

TEST(SparseChain, HeadCt) {
  const Volume v = engine::load_volume(kHead);
  for (double tau : {1150.0, 500.0}) {
    check_case(v, {PassDesc::gradient()}, above(tau), float(v.min_value), "head gradient tau " + std::to_string(tau));
    check_case(v, {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()}, above(tau),
               float(v.min_value), "head gauss 1mm tau " + std::to_string(tau), 512u << 10);
  }
}

TEST(SparseChain, ChestCt) {
  const Volume v = engine::load_volume(kChest);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()};
  check_case(v, p, above(-500), -1024.0f, "chest gauss 1mm -500", 8u << 20);
  check_case(v, p, above(250), -1024.0f, "chest gauss 1mm +250");
}

TEST(SparseChain, OneWorkgroupLoopsOverManyBricks) {
  // Asking for a single workgroup per dispatch: each workgroup loops over as many bricks as
  // llvmpipe's loop budget allows (65535 loop trips per invocation, all loops together;
  // beyond it every loop stops silently and bricks come out empty or half computed). The
  // chest at -500 HU has ~5300 candidates: ~10 workgroups of ~500 bricks each without the
  // budget. Truth: the dense CPU chain, and the same result with the default workgroups.
  const Volume v = engine::load_volume(kChest);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  const engine::SparseOutput one = run_gpu(v, p, above(-500), -1024.0f, 0, 1, Strategy::PerBrick);
  const std::size_t per = std::size_t(engine::sparse::max_bricks_per_workgroup(
      engine::sparse::make_plan(v.grid, p, "chest")));
  ASSERT_GE(per, 4u) << "the case needs several bricks per workgroup";
  EXPECT_LE(one.stats.workgroups, one.stats.candidates / per + one.stats.dispatches)
      << "one workgroup asked for: as few as the budget allows, each looping over many bricks";
  expect_matches_dense(v, p, above(-500), one, "chest -500, 1 workgroup asked for");
  const engine::SparseOutput def = run_gpu(v, p, above(-500), -1024.0f, 0, 0, Strategy::PerBrick);
  expect_same_output(one, def, "chest -500: 1 workgroup asked for vs default");
  const engine::SparseOutput dense = run_gpu(v, p, above(-500), -1024.0f, 0, 0, Strategy::Dense);
  expect_same_output(dense, def, "chest -500: dense strategy vs per-brick");
  const engine::SparseOutput lists = run_gpu(v, p, above(-500), -1024.0f, 0, 0, Strategy::Lists);
  expect_same_output(lists, def, "chest -500: lists strategy vs per-brick");
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(SparseChain, OddSizesAnisotropicBelow) {
  // Dims not multiples of 8 (partial bricks, the apron beyond the grid), anisotropic
  // spacing, inside below tau (signed distance, negative inside after negation).
  Volume v = engine::make_sphere({37, 29, 23}, 1e-3, 9.0, {1.3, -0.7, 0.4});
  for (float& f : v.voxels) f = -f;
  v.update_stats();
  v.grid.spacing_m = {0.8e-3, 1.1e-3, 1.7e-3};
  const core::Isosurface iso{0.0, core::InsideIs::kBelow};
  check_case(v, {PassDesc::gaussian(1.2), PassDesc::gradient()}, iso, 1e4f, "sphere odd dims gauss", 80u << 10);
  // Random data: nearly every brick straddles; every border rule at once.
  const Volume r = engine::make_random({19, 13, 11}, {0.7e-3, 1.1e-3, 2.3e-3}, -1000.0f, 3000.0f, 7);
  check_case(r, {PassDesc::gaussian(0.9), PassDesc::gradient()}, above(1000), -1000.0f, "random odd dims gauss");
}

TEST(SparseChain, ClosingThenGaussian) {
  const Volume v = engine::load_volume(kHead);
  const std::vector<PassDesc> p = {PassDesc::closing(1.0), PassDesc::gaussian(0.8), PassDesc::gradient()};
  check_case(v, p, above(1150), float(v.min_value), "head closing+gauss", 512u << 10);
  // The head's spacing makes a 1 mm closing radius 0; here it is 1 voxel along x.
  Volume s = engine::make_sphere({30, 27, 21}, 1e-3, 8.0, {0.5, 0.2, -0.3});
  s.grid.spacing_m = {1.0e-3, 1.6e-3, 2.5e-3};
  check_case(s, {PassDesc::closing(1.0), PassDesc::gaussian(0.5), PassDesc::gradient()}, above(0), -1e4f,
             "sphere closing+gauss", 64u << 10);
}

TEST(SparseChain, RoundingAcrossTauNeedsTheEpsilon) {
  // A constant 1000 smoothed with sigma 0.5 voxel: the float weights and the rounded sums
  // give 1000.00012 (computed outside this code: float kernel, -ffp-contract=off), above
  // tau = 1000 although every raw voxel is <= tau. The raw range alone says "uniform
  // outside"; the widened range makes every brick a candidate and the exact range says
  // "uniform inside", which is what the dense field is.
  Volume v = engine::make_random({20, 17, 12}, {1e-3, 1e-3, 1e-3}, 0.0f, 1.0f, 3);
  std::fill(v.voxels.begin(), v.voxels.end(), 1000.0f);
  v.update_stats();
  const std::vector<PassDesc> p = {PassDesc::gaussian(0.5), PassDesc::gradient()};
  const engine::ChainOutput dense = engine::run_chain_cpu(v, p);
  ASSERT_GT(dense.samples->samples[0].value, 1000.0f) << "the case needs the rounding above tau";
  const engine::SparseOutput s = run_gpu(v, p, above(1000), 0.0f);
  expect_matches_dense(v, p, above(1000), s, "constant 1000, tau 1000", false);
  const engine::SparseOutput c = engine::run_sparse_cpu(v, p, above(1000), 0.0f, core::SampleFormat::kFp32, true);
  expect_matches_dense(v, p, above(1000), c, "constant 1000, tau 1000 (CPU sparse)", false);
}

TEST(SparseChain, RejectsListsItCannotRun) {
  EXPECT_FALSE(engine::SparseChain::create(vk(), {PassDesc::gaussian(1.0)}));  // no gradient
  EXPECT_FALSE(engine::SparseChain::create(vk(), {PassDesc::gradient(), PassDesc::gaussian(1.0)}));
  EXPECT_FALSE(engine::SparseChain::create(vk(), {PassDesc::gradient(), PassDesc::brick_minmax(2)}));
  // Too wide for shared memory: an error naming the volume, not a crash.
  const Volume v = engine::make_sphere({24, 24, 24}, 1e-3, 8.0);
  auto chain = engine::SparseChain::create(vk(), {PassDesc::gaussian(4.0), PassDesc::gradient()});
  ASSERT_TRUE(chain);
  (*chain.value)->set_strategy(engine::SparseChain::Strategy::PerBrick);
  EXPECT_THROW((*chain.value)->run(v, above(0), -1e4f), engine::VolumeError);
  // The dense and lists strategies have no shared-memory limit: they run, and match the
  // dense CPU chain.
  const std::vector<PassDesc> wide = {PassDesc::gaussian(4.0), PassDesc::gradient()};
  expect_matches_dense(v, wide, above(0), run_gpu(v, wide, above(0), -1e4f, 0, 0, Strategy::Dense),
                       "sigma 4 mm (dense strategy)");
  expect_matches_dense(v, wide, above(0), run_gpu(v, wide, above(0), -1e4f, 0, 0, Strategy::Lists),
                       "sigma 4 mm (lists strategy)");
}

TEST(SparseChain, ListsRunAFilterWiderThanTheX4ShaderAsDense) {
  // Sigma 6 mm at 1 mm spacing: radius 18 > ISOTOUCH_DENSE_MAX_RADIUS taps a side, more than
  // filter_list_x4 unrolls; the lists strategy runs the dense one (whose chain takes the 1-D
  // shaders) and says so. Truth: the dense CPU chain.
  const Volume v = engine::make_sphere({40, 36, 34}, 1e-3, 12.0);
  const std::vector<PassDesc> wide = {PassDesc::gaussian(6.0), PassDesc::gradient()};
  auto chain = engine::SparseChain::create(vk(), wide);
  ASSERT_TRUE(chain) << chain.error;
  (*chain.value)->set_keep_input(true);
  const engine::SparseOutput out = (*chain.value)->run(v, above(0), -1e4f);
  EXPECT_NE((*chain.value)->describe().find("ran as dense"), std::string::npos) << (*chain.value)->describe();
  expect_matches_dense(v, wide, above(0), out, "sigma 6 mm (lists strategy, run as dense)");
}

TEST(SparseChain, WorkListsCoverTheCandidatesExtentsOnce) {
  // Brute force: the quads whose 4 voxels meet some candidate's extent (8 b - lo .. 8 b + 7
  // + hi, clipped), each exactly once, sorted by z, y, x, in units of at most
  // ISOTOUCH_LIST_QUADS quads of one row; z_first indexes the slices.
  core::Grid g;
  g.dims = {45, 30, 21};
  const auto nb = core::brick_counts(g);
  std::vector<std::uint32_t> cand;
  for (std::uint32_t id = 0; id < std::uint32_t(nb[0] * nb[1] * nb[2]); ++id)
    if ((id * 2654435761u) % 7u < 2u) cand.push_back(id);
  for (const engine::sparse::Extent e :
       {engine::sparse::Extent{{4, 1, 1}, {8, 2, 2}}, engine::sparse::Extent{{8, 3, 0}, {4, 0, 5}},
        engine::sparse::Extent{{0, 0, 0}, {4, 1, 1}}}) {
    const engine::sparse::WorkList w = engine::sparse::make_work_list(g, cand, e, "grid");
    const int qx = (g.dims[0] + 3) / 4;
    std::vector<int> want(std::size_t(qx) * std::size_t(g.dims[1]) * std::size_t(g.dims[2]), 0), got(want.size(), 0);
    for (std::uint32_t id : cand) {
      const auto b = core::brick_coords(id, nb);
      for (int z = std::max(8 * b[2] - e.lo[2], 0); z <= std::min(8 * b[2] + 7 + e.hi[2], g.dims[2] - 1); ++z)
        for (int y = std::max(8 * b[1] - e.lo[1], 0); y <= std::min(8 * b[1] + 7 + e.hi[1], g.dims[1] - 1); ++y)
          for (int x = std::max(8 * b[0] - e.lo[0], 0); x <= std::min(8 * b[0] + 7 + e.hi[0], g.dims[0] - 1); ++x)
            want[(std::size_t(z) * std::size_t(g.dims[1]) + std::size_t(y)) * std::size_t(qx) + std::size_t(x / 4)] = 1;
    }
    ASSERT_EQ(w.z_first.size(), std::size_t(g.dims[2]) + 1);
    std::uint64_t quads = 0;
    long last = -1;
    for (std::size_t u = 0; u < w.unit_count(); ++u) {
      const int row = int(w.units[2 * u]), packed = int(w.units[2 * u + 1]);
      const int z = row / g.dims[1], y = row % g.dims[1];
      const int q0 = packed / int(ISOTOUCH_LIST_PACK), n = packed % int(ISOTOUCH_LIST_PACK);
      ASSERT_TRUE(n >= 1 && n <= int(ISOTOUCH_LIST_QUADS)) << "unit " << u;
      EXPECT_TRUE(u >= w.z_first[std::size_t(z)] && u < w.z_first[std::size_t(z) + 1]) << "unit " << u << " z " << z;
      for (int q = q0; q < q0 + n; ++q) {
        ASSERT_LT(q, qx);
        const long at = (long(z) * g.dims[1] + y) * qx + q;
        EXPECT_GT(at, last) << "unit " << u << ": not sorted or a quad twice";
        last = at;
        ++got[std::size_t(at)];
        ++quads;
      }
    }
    EXPECT_EQ(got, want) << "extent lo " << e.lo[0] << "," << e.lo[1] << "," << e.lo[2];
    EXPECT_EQ(quads, w.quads);
  }
}

// ---------------------------------------------------------------- benchmark (disabled)
// ISOTOUCH_BENCH_REPS (default 5) runs; median. Run:
//   test_sparse_chain --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_Bench*'
namespace {
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}
void bench_case(const Volume& v, double tau, int reps) {
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()};
  auto ctx = engine::VulkanContext::create({});  // no validation layer: timings
  ASSERT_TRUE(ctx) << ctx.error;
  auto sparse = engine::SparseChain::create(**ctx.value, p);
  ASSERT_TRUE(sparse) << sparse.error;
  auto dense_gpu = engine::PassChain::create(**ctx.value, p);
  ASSERT_TRUE(dense_gpu) << dense_gpu.error;
  std::vector<double> sp, sp_up, sp_gpu, sp_sub, sp_down, sp_pub, dc, dg, sc;
  engine::SparseOutput last;
  for (int r = 0; r < reps; ++r) {
    auto t0 = std::chrono::steady_clock::now();
    last = (*sparse.value)->run(v, above(tau), -1024.0f);
    sp.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    sp_up.push_back(last.upload_ms);
    sp_gpu.push_back(last.submit_wall_ms);
    sp_sub.push_back(last.submit_wall_ms);
    sp_down.push_back(last.download_ms);
    sp_pub.push_back(last.publish_ms);
    t0 = std::chrono::steady_clock::now();
    const auto c = engine::run_chain_cpu(v, p);
    dc.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (std::getenv("ISOTOUCH_BENCH_QUICK")) continue;  // sparse GPU vs dense CPU only
    t0 = std::chrono::steady_clock::now();
    const auto g = (*dense_gpu.value)->run(v);
    dg.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    t0 = std::chrono::steady_clock::now();
    const auto s = engine::run_sparse_cpu(v, p, above(tau), -1024.0f);
    sc.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::printf(
      "chest tau %+.0f: %zu bricks, %zu candidates (%.1f %%), %zu active (%.1f %%)\n"
      "  sparse GPU total %.1f ms (host staging+ranges+setup %.1f, GPU (submit wall) %.1f, submit wall %.1f, readback %.1f, "
      "publish %.1f)\n  dense CPU %.1f ms  ratio sparse GPU / dense CPU = %.3f\n  dense GPU %.1f ms, sparse CPU %.1f ms"
      " (median of %d)\n",
      tau, last.stats.bricks_total, last.stats.candidates, 100.0 * double(last.stats.candidates) / double(last.stats.bricks_total),
      last.stats.active, 100.0 * double(last.stats.active) / double(last.stats.bricks_total), median(sp), median(sp_up),
      median(sp_gpu), median(sp_sub), median(sp_down), median(sp_pub), median(dc), median(sp) / median(dc),
      dg.empty() ? -1.0 : median(dg), sc.empty() ? -1.0 : median(sc), reps);
  for (const auto& st : last.passes) std::printf("    %-70s %8.2f ms\n", st.label.c_str(), st.ms);
}
}  // namespace

TEST(SparseChain, DISABLED_BenchChest) {
  const char* e = std::getenv("ISOTOUCH_BENCH_REPS");
  const int reps = e ? std::max(1, std::atoi(e)) : 5;
  const Volume v = engine::load_volume(kChest);
  bench_case(v, -500, reps);
  bench_case(v, 250, reps);
}

TEST(SparseChain, DISABLED_Bench512) {
  Volume v = engine::make_sphere({512, 512, 512}, 1e-3, 200.0);
  auto ctx = engine::VulkanContext::create({});
  ASSERT_TRUE(ctx) << ctx.error;
  auto sparse = engine::SparseChain::create(**ctx.value, {PassDesc::gaussian(1.0), PassDesc::gradient()});
  ASSERT_TRUE(sparse) << sparse.error;
  for (int r = 0; r < 2; ++r) {
    const auto out = (*sparse.value)->run(v, above(0), -1e6f);
    std::printf("512^3 sphere: total %.1f ms (upload %.1f, submit %.1f, publish %.1f), %zu candidates, %zu active\n",
                out.total_ms, out.upload_ms, out.submit_wall_ms, out.publish_ms, out.stats.candidates,
                out.stats.active);
  }
  std::printf("%s\n", (*sparse.value)->describe().c_str());
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  std::printf("peak RSS %.1f MiB\n", double(ru.ru_maxrss) / 1024.0);
}
