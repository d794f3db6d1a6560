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
#include <sys/mman.h>
#include <sys/resource.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>

#include "isotouch/tests/vk_test_context.h"
#include "isotouch/tests/gpu_cpu_compare.h"
#include "isotouch/engine/cpu_filters.h"
#include "isotouch/shaders/filter_list_x4_spv.h"
#include "isotouch/shaders/filter_x4_spv.h"
#include "isotouch/shaders/gauss_fused_list_spv.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/pool_recycler.h"
#include "isotouch/engine/sparse_chain.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"

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

// Dense CPU truth against one sparse result: samples, active set, tiles. A GPU result
// (`from_gpu`) is held to the one rule (tests/gpu_cpu_compare.h): bit for bit on a CPU
// device; on a GPU the samples of the bricks active on both sides within the ULP bound and
// at most 1 % of the bricks active on one side only (a range that straddles tau by less than
// the GPU's rounding).
void expect_matches_dense(const Volume& v, const std::vector<PassDesc>& passes, const core::Isosurface& iso,
                          const engine::SparseOutput& s, const std::string& what, bool expect_surface = true,
                          bool from_gpu = true) {
  const bool exact = !from_gpu || isotouch::test::expects_bit_identity(vk());
  std::vector<core::Sample> got_both, want_both;  // under the GPU rule: bricks active on both sides
  std::size_t one_side = 0;
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
    if (exact)
      EXPECT_EQ(slot[id] >= 0, straddles) << what << ": brick " << id << " range " << mn << ".." << mx;
    else if ((slot[id] >= 0) != straddles) {
      ++one_side;
      continue;
    }
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
          if (!exact) {
            got_both.push_back(got);
            want_both.push_back(want);
            continue;
          }
          if (!same(got, want) && wrong_samples++ < 5)
            ADD_FAILURE() << what << ": voxel " << x << "," << y << "," << z << " sparse {" << got.value << ", "
                          << got.gx << ", " << got.gy << ", " << got.gz << "} dense {" << want.value << ", " << want.gx
                          << ", " << want.gy << ", " << want.gz << "}";
        }
  }
  EXPECT_EQ(wrong_samples, 0u) << what;
  if (!exact) {
    EXPECT_LE(one_side, std::max<std::size_t>(1, brute_active / 100)) << what << ": bricks active on one side only";
    EXPECT_TRUE(isotouch::test::gpu_matches_cpu(vk(), got_both, want_both, what + ": samples of bricks active on both sides"));
  }
  EXPECT_EQ(wrong_side, 0u) << what << ": voxels on the other side of their uniform brick's tile";
  if (expect_surface) {
    EXPECT_GT(brute_active, 0u) << what << ": the case must have a surface";
  }
  std::printf("  %-40s %zu bricks, %zu candidates, %zu active (brute force %zu), %zu samples %s\n", what.c_str(), total,
              s.stats.candidates, s.stats.active, brute_active, compared - wrong_samples,
              exact ? "bit-identical" : "compared under the GPU rule");
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

/// GPU sparse against the CPU sparse reference under the one rule (tests/gpu_cpu_compare.h):
/// bit for bit on a CPU device; on a GPU the same candidates (selected on the host from the
/// raw voxels), the samples of the bricks active on both sides within the ULP bound, and at
/// most 1 % of the active bricks active on one side only (a smoothed range that straddles
/// tau by less than the GPU's rounding).
void expect_gpu_sparse_matches_cpu(const engine::SparseOutput& gpu, const engine::SparseOutput& cpu,
                                   const std::string& what) {
  if (isotouch::test::expects_bit_identity(vk())) return expect_same_output(gpu, cpu, what);
  EXPECT_EQ(gpu.stats.candidates, cpu.stats.candidates) << what;
  std::vector<core::Sample> a, b;
  std::size_t one_side = 0, i = 0, j = 0;
  const auto& ga = gpu.input.active;
  const auto& ca = cpu.input.active;
  const std::size_t n = core::kBrickSamples;
  while (i < ga.size() || j < ca.size()) {
    if (j == ca.size() || (i < ga.size() && ga[i] < ca[j])) { ++one_side, ++i; continue; }
    if (i == ga.size() || ca[j] < ga[i]) { ++one_side, ++j; continue; }
    a.insert(a.end(), gpu.input.pool.begin() + std::ptrdiff_t(i * n), gpu.input.pool.begin() + std::ptrdiff_t((i + 1) * n));
    b.insert(b.end(), cpu.input.pool.begin() + std::ptrdiff_t(j * n), cpu.input.pool.begin() + std::ptrdiff_t((j + 1) * n));
    ++i, ++j;
  }
  EXPECT_LE(one_side, std::max<std::size_t>(1, ca.size() / 100)) << what << ": bricks active on one side only";
  EXPECT_TRUE(isotouch::test::gpu_matches_cpu(vk(), a, b, what + ": samples of the bricks active on both sides"));
  // The tiles of the bricks uniform on both sides, under the same rule.
  ASSERT_EQ(gpu.input.tile.size(), cpu.input.tile.size()) << what;
  std::vector<float> ta, tb;
  for (std::size_t id = 0; id < cpu.input.tile.size(); ++id)
    if (!std::binary_search(ga.begin(), ga.end(), std::uint32_t(id)) &&
        !std::binary_search(ca.begin(), ca.end(), std::uint32_t(id))) {
      ta.push_back(gpu.input.tile[id]);
      tb.push_back(cpu.input.tile[id]);
    }
  EXPECT_TRUE(isotouch::test::gpu_matches_cpu(vk(), ta, tb, what + ": tiles of the bricks uniform on both sides"));
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
  expect_gpu_sparse_matches_cpu(gpu, cpu, what + ": GPU vs CPU sparse");
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
  const Volume v = io::load_volume(kHead);
  for (double tau : {1150.0, 500.0}) {
    check_case(v, {PassDesc::gradient()}, above(tau), float(v.min_value), "head gradient tau " + std::to_string(tau));
    check_case(v, {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()}, above(tau),
               float(v.min_value), "head gauss 1mm tau " + std::to_string(tau), 512u << 10);
  }
}

TEST(SparseChain, ChestCt) {
  const Volume v = io::load_volume(kChest);
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
  const Volume v = io::load_volume(kChest);
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
  expect_gpu_sparse_matches_cpu(dense, def, "chest -500: dense strategy vs per-brick");
  const engine::SparseOutput lists = run_gpu(v, p, above(-500), -1024.0f, 0, 0, Strategy::Lists);
  expect_gpu_sparse_matches_cpu(lists, def, "chest -500: lists strategy vs per-brick");
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
  const Volume v = io::load_volume(kHead);
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
  expect_matches_dense(v, p, above(1000), c, "constant 1000, tau 1000 (CPU sparse)", false, false);
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

TEST(SparseChain, ListsWithStagingCopiesGiveTheSameBits) {
  // Where device-local memory is not host-visible (a discrete GPU) the lists strategy
  // stages the voxels and the work lists and reads the last field back; lavapipe runs that
  // path with zero copy turned off. Truth: the dense CPU chain; and the zero-copy run.
  const Volume v = engine::make_sphere({37, 29, 23}, 1e-3, 9.0, {1.3, -0.7, 0.4});
  const std::vector<PassDesc> p = {PassDesc::closing(1.0), PassDesc::gaussian(1.0), PassDesc::gradient()};
  struct Restore {
    ~Restore() { vk().allow_zero_copy(true); }
  } restore;
  const engine::SparseOutput direct = run_gpu(v, p, above(0), -1e4f);
  vk().allow_zero_copy(false);
  ASSERT_FALSE(vk().device_local_is_host_visible());
  const engine::SparseOutput staged = run_gpu(v, p, above(0), -1e4f, 48u << 10);
  expect_matches_dense(v, p, above(0), staged, "sphere closing+gauss, staging copies, small bindings");
  expect_same_output(direct, staged, "zero copy vs staging copies");
  EXPECT_GE(staged.stats.slabs, 2u) << "the small binding must force several slabs";
}

TEST(SparseChain, RepeatedRunsReuseThePoolOfASnapshotNobodyHolds) {
  // A run publishes into the buffer of a snapshot already destroyed (its pages resident)
  // and never into one still held: a held snapshot reads the same after a later run at
  // another isovalue (other samples). Truth for the samples: the CPU sparse reference (bit
  // for bit on a CPU device).
  const Volume v = io::load_volume(kHead);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  auto chain = engine::SparseChain::create(vk(), p);
  ASSERT_TRUE(chain) << chain.error;
  engine::SparseChain& c = **chain.value;
  std::map<double, engine::SparseOutput> ref;
  for (double tau : {500.0, 1150.0})
    ref[tau] = engine::run_sparse_cpu(v, p, above(tau), -1024.0f, core::SampleFormat::kFp32, true);
  auto pool_of = [](const engine::SparseOutput& o) { return o.field.bricks->pool.get(); };
  auto check = [&](const engine::SparseOutput& o, double tau, const std::string& what) {
    ASSERT_TRUE(o.field.bricked()) << what;
    engine::SparseOutput copy;
    copy.stats = o.stats;
    copy.input.active = ref[tau].input.active;
    copy.input.tile = ref[tau].input.tile;
    copy.input.pool.assign(pool_of(o)->begin(), pool_of(o)->end());
    if (isotouch::test::expects_bit_identity(vk())) expect_same_output(copy, ref[tau], what);
  };
  auto first = std::make_unique<engine::SparseOutput>(c.run(v, above(500), -1024.0f));
  check(*first, 500, "first run, +500");
  EXPECT_EQ(c.retained_pool_bytes(), 0u);
  // On any device: the held snapshot's bytes do not change while later runs publish.
  const std::vector<core::Sample> first_bytes(pool_of(*first)->begin(), pool_of(*first)->end());
  auto held_unchanged = [&](const std::string& when) {
    ASSERT_EQ(pool_of(*first)->size(), first_bytes.size()) << when;
    EXPECT_EQ(std::memcmp(pool_of(*first)->data(), first_bytes.data(), first_bytes.size() * sizeof(core::Sample)), 0)
        << "the held first snapshot changed " << when;
  };
  {
    const engine::SparseOutput second = c.run(v, above(1150), -1024.0f);  // the first is still held
    EXPECT_EQ(c.recycled_pools(), 0u);
    check(second, 1150, "second run, +1150, the first held");
    held_unchanged("during the second run");
  }
  check(*first, 500, "the held first snapshot after the second run");
  held_unchanged("after the second run");
  EXPECT_GT(c.retained_pool_bytes(), 0u) << "the second snapshot died: its buffer is retained";
  first.reset();  // both buffers free now: the larger is kept, the other freed
  EXPECT_GE(c.retained_pool_bytes(), ref[500].input.pool.size() * sizeof(core::Sample));
  std::uint64_t third_bytes = 0;
  {
    const engine::SparseOutput third = c.run(v, above(500), -1024.0f);
    EXPECT_EQ(c.recycled_pools(), 1u);
    EXPECT_EQ(c.retained_pool_bytes(), 0u) << "the retained buffer went into the third snapshot";
    check(third, 500, "third run, +500, into a recycled pool");
    third_bytes = pool_of(third)->capacity() * sizeof(core::Sample);
  }
  // A run needing less than half the retained buffer gets fresh memory (a small snapshot
  // never pins a large buffer); the large one stays retained for a later large run.
  ASSERT_EQ(c.retained_pool_bytes(), third_bytes);
  const engine::SparseOutput small = c.run(v, above(2600), -1024.0f);
  ASSERT_GT(small.stats.active, 0u);
  ASSERT_LT(2 * pool_of(small)->size() * sizeof(core::Sample), third_bytes) << "+2600 HU is not a small run here";
  EXPECT_EQ(c.recycled_pools(), 1u) << "a small run took the large retained buffer";
  EXPECT_EQ(c.retained_pool_bytes(), third_bytes);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(SparseChain, CpuBackendThreadsGiveTheReferenceBitForBit) {
  // The multi-threaded sparse CPU backend (candidates split among threads) against the
  // one-thread reference and the dense CPU chain: the same bricks, tiles and samples.
  const Volume v = io::load_volume(kChest);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  const engine::SparseOutput one = engine::run_sparse_cpu(v, p, above(-500), -1024.0f, core::SampleFormat::kFp32, true);
  for (unsigned threads : {2u, 3u}) {
    const engine::SparseOutput many =
        engine::run_sparse_cpu(v, p, above(-500), -1024.0f, core::SampleFormat::kFp32, true, threads);
    std::printf("  chest -500 sparse CPU: %u threads %.1f ms, one thread %.1f ms\n", threads, many.total_ms,
                one.total_ms);
    expect_same_output(one, many, "sparse CPU, " + std::to_string(threads) + " threads vs one");
  }
  const Volume odd = engine::make_random({19, 13, 11}, {0.7e-3, 1.1e-3, 2.3e-3}, -1000.0f, 3000.0f, 7);
  const std::vector<PassDesc> q = {PassDesc::closing(1.0), PassDesc::gaussian(0.9), PassDesc::gradient()};
  expect_matches_dense(odd, q, above(1000),
                       engine::run_sparse_cpu(odd, q, above(1000), -1000.0f, core::SampleFormat::kFp32, true, 3),
                       "random odd dims, sparse CPU 3 threads", /*expect_surface=*/true, /*from_gpu=*/false);
}

namespace {
/// Brute force: 1 for every quad (4 voxels of an x-row, `qx` per row; index (z ny + y) qx +
/// x / 4) with a voxel in some candidate's extent 8 b - lo .. 8 b + 7 + hi (clipped).
std::vector<int> quads_meeting(const core::Grid& g, const std::vector<std::uint32_t>& cand,
                               const engine::sparse::Extent& e, int qx) {
  const auto nb = core::brick_counts(g);
  std::vector<int> want(std::size_t(qx) * std::size_t(g.dims[1]) * std::size_t(g.dims[2]), 0);
  for (std::uint32_t id : cand) {
    const auto b = core::brick_coords(id, nb);
    for (int z = std::max(8 * b[2] - e.lo[2], 0); z <= std::min(8 * b[2] + 7 + e.hi[2], g.dims[2] - 1); ++z)
      for (int y = std::max(8 * b[1] - e.lo[1], 0); y <= std::min(8 * b[1] + 7 + e.hi[1], g.dims[1] - 1); ++y)
        for (int x = std::max(8 * b[0] - e.lo[0], 0); x <= std::min(8 * b[0] + 7 + e.hi[0], g.dims[0] - 1); ++x)
          want[(std::size_t(z) * std::size_t(g.dims[1]) + std::size_t(y)) * std::size_t(qx) + std::size_t(x / 4)] = 1;
  }
  return want;
}
}  // namespace

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
    const std::vector<int> want = quads_meeting(g, cand, e, qx);
    std::vector<int> got(want.size(), 0);
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

TEST(SparseChain, ColumnListsCoverTheCandidatesExtentsOnce) {
  // Brute force as above for the fused Gaussian's columns: units (q + QX z, y0 * PACK + n)
  // name the quads whose voxels meet some candidate's extent, each exactly once, sorted by z,
  // 1 <= n < ISOTOUCH_LIST_PACK, the longest first within a slice; paired, (2 (q + QX z) + pair, ...) where a pair names its
  // rows in slices z and z + 1, and slices that need the same rows do share units.
  core::Grid g;
  g.dims = {44, 37, 21};
  const auto nb = core::brick_counts(g);
  std::vector<std::uint32_t> cand;
  for (std::uint32_t id = 0; id < std::uint32_t(nb[0] * nb[1] * nb[2]); ++id)
    if ((id * 2654435761u) % 7u < 2u) cand.push_back(id);
  for (const engine::sparse::Extent e :
       {engine::sparse::Extent{{4, 1, 1}, {4, 2, 2}}, engine::sparse::Extent{{8, 3, 0}, {4, 0, 5}},
        engine::sparse::Extent{{0, 0, 0}, {4, 1, 1}}}) {
    for (const bool paired : {false, true}) {
    const engine::sparse::WorkList w = engine::sparse::make_column_list(g, cand, e, "grid", paired);
    const int qx = g.dims[0] / 4;
    const std::vector<int> want = quads_meeting(g, cand, e, qx);
    std::vector<int> got(want.size(), 0);
    ASSERT_EQ(w.z_first.size(), std::size_t(g.dims[2]) + 1);
    std::uint64_t quads = 0, pairs = 0;
    for (std::size_t u = 0; u < w.unit_count(); ++u) {
      const int a2 = int(w.units[2 * u]), packed = int(w.units[2 * u + 1]);
      const int pair = paired ? a2 & 1 : 0, a = paired ? a2 >> 1 : a2;
      const int z = a / qx, q = a % qx;
      const int y0 = packed / int(ISOTOUCH_LIST_PACK), n = packed % int(ISOTOUCH_LIST_PACK);
      ASSERT_TRUE(n >= 1 && y0 + n <= g.dims[1] && z + pair < g.dims[2]) << "unit " << u;
      EXPECT_TRUE(u >= w.z_first[std::size_t(z)] && u < w.z_first[std::size_t(z) + 1]) << "unit " << u << " z " << z;
      pairs += std::uint64_t(pair);
      for (int zz = z; zz <= z + pair; ++zz)
        for (int y = y0; y < y0 + n; ++y) {
          ++got[(std::size_t(zz) * std::size_t(g.dims[1]) + std::size_t(y)) * std::size_t(qx) + std::size_t(q)];
          ++quads;
        }
    }
    EXPECT_EQ(got, want) << "extent lo " << e.lo[0] << "," << e.lo[1] << "," << e.lo[2] << (paired ? ", paired" : "");
    // Within a slice the longest columns come first (llvmpipe's lanes run alike lengths).
    for (std::size_t z = 0; z < std::size_t(g.dims[2]); ++z)
      for (std::size_t u = w.z_first[z] + 1; u < w.z_first[z + 1]; ++u)
        EXPECT_GE(int(w.units[2 * u - 1]) % int(ISOTOUCH_LIST_PACK), int(w.units[2 * u + 1]) % int(ISOTOUCH_LIST_PACK))
            << "slice " << z << " unit " << u;
    EXPECT_EQ(quads, w.quads);
    if (paired) {
      EXPECT_GT(pairs, 0u) << "no slices share units";
      // The slice pairs split among 2, 3, 7 and 40 threads give the same list (40: more
      // threads than pairs, so at most one pair per part).
      for (const unsigned threads : {2u, 3u, 7u, 40u}) {
        const engine::sparse::WorkList t = engine::sparse::make_column_list(g, cand, e, "grid", true, threads);
        EXPECT_EQ(t.units, w.units) << threads << " threads";
        EXPECT_EQ(t.z_first, w.z_first) << threads << " threads";
        EXPECT_EQ(t.quads, w.quads) << threads << " threads";
      }
    }
    }
  }
}

TEST(SparseChain, CpuReferencePublishesIntoARecycledPoolTheSameBits) {
  // run_sparse_cpu with a PoolRecycler: a second run publishes into the buffer of the first
  // snapshot once it is dropped, with the bytes of a run into a fresh pool; a snapshot still
  // held is never written by a later run.
  const Volume v = io::load_volume(kHead);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  const auto f32 = core::SampleFormat::kFp32;
  const engine::SparseOutput ref = engine::run_sparse_cpu(v, p, above(500), -1024.0f, f32, true);
  auto pools = std::make_shared<engine::PoolRecycler>();
  auto bytes_of = [](const engine::SparseOutput& o) {
    const auto* pool = o.field.bricks->pool.get();
    return std::vector<core::Sample>(pool->begin(), pool->end());
  };
  auto same = [](const std::vector<core::Sample>& a, const auto& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(core::Sample)) == 0;
  };
  (void)engine::run_sparse_cpu(v, p, above(500), -1024.0f, f32, false, 1, pools);  // dropped at once
  EXPECT_EQ(pools->reuses(), 0u);
  const engine::SparseOutput held = engine::run_sparse_cpu(v, p, above(500), -1024.0f, f32, false, 2, pools);
  EXPECT_EQ(pools->reuses(), 1u) << "the second run did not take the first snapshot's buffer";
  ASSERT_TRUE(held.field.bricked());
  const std::vector<core::Sample> held_bytes = bytes_of(held);
  EXPECT_TRUE(same(held_bytes, ref.input.pool)) << "a recycled pool's samples differ from a fresh one's";
  const engine::SparseOutput other = engine::run_sparse_cpu(v, p, above(1150), -1024.0f, f32, false, 1, pools);
  EXPECT_EQ(pools->reuses(), 1u) << "a run took the buffer of a snapshot still held";
  EXPECT_TRUE(same(held_bytes, *held.field.bricks->pool)) << "the held snapshot changed during a later run";
}

// GpuBuffer::import_host: the pages holding a host range become a buffer whose bytes at
// `offset` are the range's own (truth: the host memory itself, read back by a GPU copy),
// for ranges starting anywhere in a page.
TEST(SparseChain, ImportedHostMemoryIsTheHostsBytes) {
  const VkDeviceSize align = vk().host_import_alignment();
  if (align == 0) GTEST_SKIP() << vk().info().name << " does not import host memory";
  std::vector<float> host(5000);
  for (std::size_t i = 0; i < host.size(); ++i) host[i] = float(i) * 0.5f - 7.0f;
  for (const std::size_t first : {std::size_t(0), std::size_t(1), std::size_t(3), std::size_t(1029)}) {
    const float* p = host.data() + first;
    const VkDeviceSize bytes = (host.size() - first) * 4;
    VkDeviceSize offset = 0;
    auto imported = engine::GpuBuffer::import_host(vk(), p, bytes, "test range", offset);
    ASSERT_TRUE(imported) << imported.error;
    const engine::GpuBuffer& b = *imported.value;
    EXPECT_EQ(offset, VkDeviceSize(reinterpret_cast<std::uintptr_t>(p) % align)) << "first " << first;
    EXPECT_EQ(b.size() % align, 0u);
    ASSERT_GE(b.size(), offset + bytes);
    engine::GpuBuffer back = engine::make_buffer_or_throw(vk(), b.size(), engine::MemoryIntent::Readback, "back");
    VkCommandBuffer cmd = vk().begin_commands();
    engine::record_copy(cmd, b, back, b.size());
    engine::barrier_transfer_to_host(cmd);
    vk().submit_and_wait(cmd);
    EXPECT_EQ(std::memcmp(static_cast<const char*>(back.mapped()) + offset, p, bytes), 0) << "first " << first;
  }
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

TEST(SparseChain, FusedGaussianWithStagingCopiesGivesTheSameBits) {
  // The fused one-pass Gaussian (rows of whole quads, radii <= ISOTOUCH_FUSED_MAX_RADIUS)
  // with zero copy and with staging copies, at a border-heavy size (every brick touches a
  // face): truth the dense CPU chain.
  const Volume v = engine::make_sphere({36, 29, 23}, 1e-3, 9.0, {1.3, -0.7, 0.4});
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.2), PassDesc::gradient()};  // radius 4: the widest fused
  struct Restore {
    ~Restore() {
      vk().allow_zero_copy(true);
      vk().allow_host_import(true);
    }
  } restore;
  auto chain = engine::SparseChain::create(vk(), p);
  ASSERT_TRUE(chain) << chain.error;
  (*chain.value)->set_keep_input(true);
  const engine::SparseOutput direct = (*chain.value)->run(v, above(0), -1e4f);
  EXPECT_NE((*chain.value)->describe().find("fused"), std::string::npos) << (*chain.value)->describe();
  expect_matches_dense(v, p, above(0), direct, "sphere gauss 1.2 mm, fused, zero copy");
  // Where the device imports host memory (lavapipe), the pass above read the volume's own
  // voxels; with import off they are copied into the input field: the same bits.
  ASSERT_FALSE(direct.passes.empty());
  EXPECT_EQ(direct.passes[0].label.find("input imported") != std::string::npos, vk().host_import_alignment() > 0)
      << direct.passes[0].label;
  vk().allow_host_import(false);
  const engine::SparseOutput copied = run_gpu(v, p, above(0), -1e4f);
  EXPECT_NE(copied.passes[0].label.find("input copy"), std::string::npos) << copied.passes[0].label;
  expect_same_output(direct, copied, "fused: imported voxels vs copied");
  vk().allow_host_import(true);
  vk().allow_zero_copy(false);
  ASSERT_FALSE(vk().device_local_is_host_visible());
  const engine::SparseOutput staged = run_gpu(v, p, above(0), -1e4f);
  expect_matches_dense(v, p, above(0), staged, "sphere gauss 1.2 mm, fused, staging copies");
  expect_same_output(direct, staged, "fused: zero copy vs staging copies");
}

// select() (separable folds over slices, threads) and select_brick() (one brick's window
// read directly, as the live field does) agree bit for bit on every brick, and every brick
// whose smoothed brick + 1 voxel straddles tau (brute force on the dense CPU chain) is a
// candidate, on the CT volumes and on a volume with NaN voxels and -0.
TEST(SparseChain, SelectionOverTheWindowsPerBrickAndBulkAgree) {
  Volume noisy = engine::make_sphere({37, 29, 21}, 1e-3, 9.0);
  for (std::size_t i = 0; i < noisy.voxels.size(); i += 997) noisy.voxels[i] = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 5; i < noisy.voxels.size(); i += 101) noisy.voxels[i] = -0.0f;
  const Volume head = io::load_volume(kHead), chest = io::load_volume(kChest);
  struct Case {
    const Volume* v;
    double tau;
  };
  for (const Case& c : {Case{&head, 500.0}, Case{&chest, -500.0}, Case{&noisy, 0.0}})
  for (const std::vector<PassDesc>& p : {std::vector<PassDesc>{PassDesc::gaussian(1.0), PassDesc::gradient()},
                                         std::vector<PassDesc>{PassDesc::gradient()}}) {
    const engine::sparse::Plan plan = engine::sparse::make_plan(c.v->grid, p, c.v->path);
    const engine::sparse::Selection sel = engine::sparse::select(c.v->grid, c.v->voxels.data(), plan, above(c.tau), 2);
    const engine::sparse::Selection one = engine::sparse::select(c.v->grid, c.v->voxels.data(), plan, above(c.tau), 1);
    EXPECT_EQ(sel.candidates, one.candidates) << c.v->path;
    // The input copy written in the same pass (2 threads, each its own slices): every voxel.
    std::vector<float> copy(c.v->voxels.size(), 7.0f);
    const engine::sparse::Selection with_copy =
        engine::sparse::select(c.v->grid, c.v->voxels.data(), plan, above(c.tau), 2, copy.data());
    EXPECT_EQ(with_copy.candidates, sel.candidates) << c.v->path;
    EXPECT_EQ(std::memcmp(copy.data(), c.v->voxels.data(), copy.size() * 4), 0) << c.v->path << ": the input copy";
    std::vector<std::uint8_t> cand(sel.lo.size(), 0);
    for (std::uint32_t id : sel.candidates) cand[id] = 1;
    std::size_t differ = 0;
    for (std::uint32_t id = 0; id < sel.lo.size(); ++id) {
      const auto b = engine::sparse::select_brick(c.v->grid, c.v->voxels.data(), plan, above(c.tau), id);
      differ += bits(b.lo) != bits(sel.lo[id]) || bits(b.hi) != bits(sel.hi[id]) || b.nan != (sel.nan[id] != 0) ||
                b.candidate != (cand[id] != 0);
    }
    EXPECT_EQ(differ, 0u) << c.v->path << ": bricks where select_brick differs from select";
    // Brute force: a brick whose smoothed brick + 1 voxel holds voxels on both sides of tau.
    const engine::ChainOutput d = engine::run_chain_cpu(*c.v, p);
    const core::Grid& g = c.v->grid;
    const auto nb = core::brick_counts(g);
    std::size_t missed = 0, straddling = 0;
    for (std::uint32_t id = 0; id < sel.lo.size(); ++id) {
      const auto b = core::brick_coords(id, nb);
      bool in = false, out = false;
      for (int z = std::max(8 * b[2] - 1, 0); z < std::min(8 * b[2] + 9, g.dims[2]); ++z)
        for (int y = std::max(8 * b[1] - 1, 0); y < std::min(8 * b[1] + 9, g.dims[1]); ++y)
          for (int x = std::max(8 * b[0] - 1, 0); x < std::min(8 * b[0] + 9, g.dims[0]); ++x) {
            const float f = d.samples->samples[g.index(x, y, z)].value;
            if (f != f) continue;
            (above(c.tau).contains(f) ? in : out) = true;
          }
      straddling += in && out;
      missed += in && out && !cand[id];
    }
    EXPECT_EQ(missed, 0u) << c.v->path << ": straddling bricks that are no candidates";
    EXPECT_GT(straddling, 0u) << c.v->path;
    std::printf("  %s tau %g, %zu passes: %zu candidates, %zu straddling (brute force)\n", c.v->path.c_str(), c.tau,
                p.size(), sel.candidates.size(), straddling);
  }
}

// candidate_ranges (the lists strategy's host step) against a brute-force fold over each
// brick + 1 voxel, every brick a candidate, on odd dims (bricks cut by the grid on every
// axis, rows of 10 and of fewer voxels), NaN voxels and -0, 1 and 2 threads.
/// Min and max of the non-NaN values (+0 for -0) and whether a NaN was seen, over brick `b`'s
/// window (8 b - 1 .. 8 b + 8 on each axis, clamped to the grid) of `f`: brute force.
struct BruteRange {
  float lo, hi;
  bool nan;
};
BruteRange brute_range(const core::Grid& g, const float* f, const std::array<int, 3>& b) {
  BruteRange e{std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(), false};
  for (int z = std::max(8 * b[2] - 1, 0); z <= std::min(8 * b[2] + 8, g.dims[2] - 1); ++z)
    for (int y = std::max(8 * b[1] - 1, 0); y <= std::min(8 * b[1] + 8, g.dims[1] - 1); ++y)
      for (int x = std::max(8 * b[0] - 1, 0); x <= std::min(8 * b[0] + 8, g.dims[0] - 1); ++x) {
        const float v = f[g.index(x, y, z)];
        if (v != v) {
          e.nan = true;
          continue;
        }
        e.lo = std::min(e.lo, v);
        e.hi = std::max(e.hi, v);
      }
  e.lo += 0.0f;
  e.hi += 0.0f;
  return e;
}

TEST(SparseChain, CandidateRangesAreTheBruteForceRanges) {
  core::Grid g;
  g.dims = {301, 61, 37};  // x bricks of 10 voxels and a last one of 6; 1520 bricks: 2 threads run
  std::vector<float> f(g.voxel_count());
  std::uint64_t s = 0x9e3779b97f4a7c15ull;
  for (float& v : f) {
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    v = float(std::int64_t(s >> 40) % 2001 - 1000) * 0.25f;
  }
  for (std::size_t i = 3; i < f.size(); i += 1013) f[i] = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 11; i < f.size(); i += 97) f[i] = -0.0f;
  const auto nb = core::brick_counts(g);
  const std::size_t total = std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]);
  std::vector<std::uint32_t> all(total);
  for (std::uint32_t i = 0; i < all.size(); ++i) all[i] = i;
  for (unsigned threads : {1u, 2u}) {
    const auto r = engine::sparse::candidate_ranges(g, f.data(), all, threads);
    ASSERT_EQ(r.size(), all.size());
    std::size_t differ = 0, with_nan = 0;
    for (std::uint32_t id : all) {
      const BruteRange e = brute_range(g, f.data(), core::brick_coords(id, nb));
      with_nan += e.nan;
      differ += bits(r[id].lo) != bits(e.lo) || bits(r[id].hi) != bits(e.hi) || r[id].nan != e.nan;
    }
    EXPECT_EQ(differ, 0u) << threads << " thread(s)";
    EXPECT_GT(with_nan, 0u);
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

// The lists strategy's host stages alone on the chest at -500, min and median of
// ISOTOUCH_BENCH_REPS (default 7) runs each, interleaved: the selection with and without the
// input copy written in the same pass, a plain memcpy of the input, the candidate ranges.
//   test_sparse_chain --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_HostStagesChest*'
// CandidateCpu (the live field's and the CPU reference's per-brick code): each brick's range
// over its window (8 b - 1 .. 8 b + 8, clamped) against brute force, on grids whose last x
// brick leaves a window row of 2 and of 3 voxels (the reduction's scalar tail) and of 10,
// with NaN and -0 among the values. Gradient only (no filter): the range is the raw voxels'.
TEST(SparseChain, CandidateCpuRangesAreTheBruteForceRanges) {
  for (int nx : {33, 34, 40}) {
    Volume v = engine::make_random({nx, 19, 11}, {1e-3, 1e-3, 1e-3}, -1.0f, 1.0f, 7);
    std::vector<float>& f = v.voxels;
    for (std::size_t i = 5; i < f.size(); i += 211) f[i] = std::numeric_limits<float>::quiet_NaN();
    for (std::size_t i = 2; i < f.size(); i += 23) f[i] = -0.0f;
    for (std::size_t i = 7; i < f.size(); i += 29) f[i] = 0.0f;
    const core::Grid& g = v.grid;
    const engine::sparse::Plan plan = engine::sparse::make_plan(g, {PassDesc::gradient()}, "random");
    engine::sparse::CandidateCpu cpu(v, plan);
    const auto nb = core::brick_counts(g);
    std::size_t differ = 0, with_nan = 0, bricks = 0;
    for (std::uint32_t id = 0; id < std::uint32_t(nb[0] * nb[1] * nb[2]); ++id, ++bricks) {
      const BruteRange e = brute_range(g, f.data(), core::brick_coords(id, nb));
      const auto r = cpu.range(id);
      with_nan += e.nan;
      differ += bits(r.lo) != bits(e.lo) || bits(r.hi) != bits(e.hi) || r.nan != e.nan;
    }
    EXPECT_EQ(differ, 0u) << "nx " << nx << ", " << bricks << " bricks";
    EXPECT_GT(with_nan, 0u);
  }
}

TEST(SparseChain, DISABLED_HostStagesChest) {
  const char* e = std::getenv("ISOTOUCH_BENCH_REPS");
  const int reps = e ? std::max(1, std::atoi(e)) : 7;
  const Volume v = io::load_volume(kChest);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  const engine::sparse::Plan plan = engine::sparse::make_plan(v.grid, p, "chest");
  const unsigned th = engine::hardware_threads();
  std::vector<float> copy(v.voxels.size(), 0.0f);
  std::vector<double> t_sel, t_sel_copy, t_memcpy, t_ranges;
  std::vector<std::uint32_t> cands;
  auto ms = [](auto&& f) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  };
  std::vector<double> t_sel1, t_sel_copy1;
  for (int r = 0; r < reps; ++r) {
    t_sel1.push_back(ms([&] { (void)engine::sparse::select(v.grid, v.voxels.data(), plan, above(-500), 1); }));
    t_sel_copy1.push_back(
        ms([&] { (void)engine::sparse::select(v.grid, v.voxels.data(), plan, above(-500), 1, copy.data()); }));
    t_sel.push_back(ms([&] { cands = engine::sparse::select(v.grid, v.voxels.data(), plan, above(-500), th).candidates; }));
    t_sel_copy.push_back(
        ms([&] { (void)engine::sparse::select(v.grid, v.voxels.data(), plan, above(-500), th, copy.data()); }));
    t_memcpy.push_back(ms([&] { std::memcpy(copy.data(), v.voxels.data(), copy.size() * 4); }));
    t_ranges.push_back(ms([&] { (void)engine::sparse::candidate_ranges(v.grid, copy.data(), cands, th); }));
  }
  auto row = [&](const char* what, std::vector<double> t) {
    std::sort(t.begin(), t.end());
    std::printf("  %-48s min %7.2f ms, median %7.2f ms\n", what, t.front(), t[t.size() / 2]);
  };
  double load[3] = {0, 0, 0};
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf %lf %lf", &load[0], &load[1], &load[2]) != 3) load[0] = -1;
    std::fclose(f);
  }
  std::printf("chest -500, %zu candidates, %u threads, %d runs, load %.2f %.2f %.2f\n", cands.size(), th, reps, load[0],
              load[1], load[2]);
  row("selection, one thread", t_sel1);
  row("selection + input copy, one thread", t_sel_copy1);
  row("selection", t_sel);
  row("selection + input copy in the same pass", t_sel_copy);
  row("input memcpy alone (one thread)", t_memcpy);
  row("candidate ranges", t_ranges);
}

TEST(SparseChain, DISABLED_BenchChest) {
  const char* e = std::getenv("ISOTOUCH_BENCH_REPS");
  const int reps = e ? std::max(1, std::atoi(e)) : 5;
  const Volume v = io::load_volume(kChest);
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

// The limit of the lists strategy on this machine, measured (not inferred): chest at -500 HU,
// each stage next to the least its work can cost here, done the cheapest way:
// - input: memcpy of the voxels into a kept buffer (the bytes the passes must start from);
// - filters: the fused pass (gauss_fused_list) with one tap per axis (radius 0, weight 1: a
//   texel fetch and a store per output quad, no arithmetic) over the same columns:
//   lavapipe's cost of touching those quads at all (and, for comparison, the three separate
//   one-tap passes of filter_list_x4 over the per-op work lists);
// - publication: memcpy of the active bricks' 729 samples each into a fresh pool (the bytes
//   the published snapshot must receive, page faults included, huge pages asked for).
// The sum of the floors over the one-thread dense CPU chain is the best ratio this design
// can reach here. Run:
//   test_sparse_chain --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_LimitChest*'
TEST(SparseChain, DISABLED_LimitChest) {
  const char* e = std::getenv("ISOTOUCH_BENCH_REPS");
  const int reps = e ? std::max(1, std::atoi(e)) : 7;
  const Volume v = io::load_volume(kChest);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()};
  auto ctxr = engine::VulkanContext::create({});  // no validation layer: timings
  ASSERT_TRUE(ctxr) << ctxr.error;
  engine::VulkanContext& ctx = **ctxr.value;
  auto chain = engine::SparseChain::create(ctx, p);
  ASSERT_TRUE(chain) << chain.error;
  const core::Isosurface iso = above(-500);
  const engine::sparse::Plan plan = engine::sparse::make_plan(v.grid, p, "chest");
  const std::size_t n = v.grid.voxel_count();
  const engine::sparse::Selection sel = engine::sparse::select(v.grid, v.voxels.data(), plan, iso);
  const auto ext = engine::sparse::list_extents(plan);
  std::vector<engine::sparse::WorkList> lists;
  std::vector<float> all;
  std::vector<std::uint32_t> base;
  for (const auto& x : ext) {
    lists.push_back(engine::sparse::make_work_list(v.grid, sel.candidates, x, "chest"));
    base.push_back(std::uint32_t(all.size() / 2));
    all.insert(all.end(), lists.back().units.begin(), lists.back().units.end());
  }
  auto buf = [&](std::uint64_t bytes, const char* what) {
    auto r = engine::GpuBuffer::create(ctx, bytes, engine::MemoryIntent::DeviceLocal, what);
    if (!r) throw std::runtime_error(r.error);
    return std::move(*r.value);
  };
  ASSERT_TRUE(ctx.device_local_is_host_visible()) << "the floors assume zero copy (lavapipe)";
  engine::GpuBuffer f0 = buf(n * 4, "field 0"), f1 = buf(n * 4, "field 1"), lb = buf(all.size() * 4, "lists");
  std::memcpy(lb.mapped(), all.data(), all.size() * 4);
  std::memset(f1.mapped(), 0, n * 4);
  std::vector<std::uint32_t> spec(6 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 2, 0u);
  for (int a = 0; a < 3; ++a) spec[std::size_t(a)] = std::uint32_t(v.grid.dims[std::size_t(a)]);
  const float one = 1.0f;
  std::memcpy(&spec[5], &one, 4);  // radius 0, weight 1: dst = 1 * src
  spec[5 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 2] = 1u;  // quad input, as the chain's own passes here
  engine::ComputePipeline<gpu::ListPush> copy(ctx, filter_list_x4_spv, 3, "filter_list_x4 r=0", 0u,
                                              spec, 0b101u);
  copy.set_texel_vec4(1u);
  auto floor_filters = [&] {
    engine::DescriptorArena arena(ctx, 8, 24);
    engine::GpuTimer timer(ctx, 2);
    VkCommandBuffer cmd = ctx.begin_commands();
    timer.record_reset(cmd);
    timer.mark(cmd, 0);
    for (std::size_t k = 0; k < lists.size(); ++k) {
      const auto& w = lists[k];
      gpu::ListPush pc{};
      pc.unit0 = base[k];
      pc.units = std::uint32_t(w.unit_count());
      const std::uint64_t groups =
          (std::uint64_t(pc.units) * ISOTOUCH_LIST_INVOCATIONS + ISOTOUCH_DENSE_WG - 1) / ISOTOUCH_DENSE_WG;
      pc.groups_x = std::uint32_t(std::min<std::uint64_t>(groups, 65535));
      pc.vec4_out = 1;
      const engine::GpuBuffer& src = k % 2 ? f1 : f0;
      const engine::GpuBuffer& dst = k % 2 ? f0 : f1;
      copy.bind(cmd, arena, {{src.handle(), 0, n * 4}, {dst.handle(), 0, n * 4}, {lb.handle(), 0, all.size() * 4}});
      copy.push(cmd, pc);
      vkCmdDispatch(cmd, pc.groups_x, std::uint32_t((groups + pc.groups_x - 1) / pc.groups_x), 1);
      engine::barrier_compute_to_compute(cmd);
    }
    timer.mark(cmd, 1);
    engine::barrier_compute_to_host(cmd);
    ctx.submit_and_wait(cmd);
    return timer.elapsed_ms(0, 1);
  };
  // The fused Gaussian's own floor: gauss_fused_list with one tap per axis (radius 0, weight
  // 1: per output quad one texel fetch and one vec4 store) over the same columns.
  const engine::sparse::WorkList columns = engine::sparse::make_column_list(v.grid, sel.candidates, ext.back(), "chest");
  engine::GpuBuffer cb = buf(columns.units.size() * 4, "columns");
  std::memcpy(cb.mapped(), columns.units.data(), columns.units.size() * 4);
  engine::ComputePipeline<gpu::ListPush> fused_copy(ctx, gauss_fused_list_spv, 3, "gauss_fused_list r=0", 0u,
                                                    engine::fused_gaussian_spec(v.grid.dims, {{{1.0f}, {1.0f}, {1.0f}}}),
                                                    0b101u);
  fused_copy.set_texel_vec4(1u);
  auto floor_fused = [&] {
    engine::DescriptorArena arena(ctx, 2, 6);
    engine::GpuTimer timer(ctx, 2);
    VkCommandBuffer cmd = ctx.begin_commands();
    timer.record_reset(cmd);
    timer.mark(cmd, 0);
    gpu::ListPush pc{};
    pc.units = std::uint32_t(columns.unit_count());
    const std::uint32_t groups = (pc.units + ISOTOUCH_DENSE_WG - 1) / ISOTOUCH_DENSE_WG;
    pc.groups_x = std::min<std::uint32_t>(groups, 65535);
    fused_copy.bind(cmd, arena, {{f0.handle(), 0, n * 4}, {f1.handle(), 0, n * 4}, {cb.handle(), 0, cb.size()}});
    fused_copy.push(cmd, pc);
    vkCmdDispatch(cmd, pc.groups_x, (groups + pc.groups_x - 1) / pc.groups_x, 1);
    timer.mark(cmd, 1);
    engine::barrier_compute_to_host(cmd);
    ctx.submit_and_wait(cmd);
    return timer.elapsed_ms(0, 1);
  };
  // The same one-tap pass, dense (filter_x4 over every quad of the volume), 3 times: what
  // the work lists cost beyond the quads they name.
  engine::ComputePipeline<gpu::DensePush> dense_copy(ctx, filter_x4_spv, 2, "filter_x4 r=0", 0u, spec, 1u);
  dense_copy.set_texel_vec4(1u);
  auto floor_dense = [&] {
    engine::DescriptorArena arena(ctx, 8, 24);
    engine::GpuTimer timer(ctx, 2);
    VkCommandBuffer cmd = ctx.begin_commands();
    timer.record_reset(cmd);
    timer.mark(cmd, 0);
    for (int k = 0; k < 3; ++k) {
      gpu::DensePush pc{};
      pc.nx = std::uint32_t(v.grid.dims[0]);
      pc.ny = std::uint32_t(v.grid.dims[1]);
      pc.nz = std::uint32_t(v.grid.dims[2]);
      pc.slab_nz = pc.nz;
      pc.qx = (pc.nx + 3) / 4;
      pc.vec4_out = 1;
      const engine::GpuBuffer& src = k % 2 ? f1 : f0;
      const engine::GpuBuffer& dst = k % 2 ? f0 : f1;
      dense_copy.bind(cmd, arena, {{src.handle(), 0, n * 4}, {dst.handle(), 0, n * 4}});
      dense_copy.push(cmd, pc);
      vkCmdDispatch(cmd, (pc.qx * pc.ny + ISOTOUCH_DENSE_WG - 1) / ISOTOUCH_DENSE_WG, 1, pc.nz);
      engine::barrier_compute_to_compute(cmd);
    }
    timer.mark(cmd, 1);
    engine::barrier_compute_to_host(cmd);
    ctx.submit_and_wait(cmd);
    return timer.elapsed_ms(0, 1);
  };
  std::size_t n_active = 0;
  std::vector<double> t_total, t_dense, t_in, t_filters, t_pub, t_gpu, t_host, t_dense_floor, t_fused, t_cpu;
  // CPU time of the whole process (lavapipe's threads included): the work a run does,
  // less sensitive than wall time to other processes on a shared machine.
  const auto process_cpu_ms = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return (double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) * 1e3 + double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) / 1e3);
  };
  engine::SparseOutput last;
  for (int r = -1; r < reps; ++r) {  // r = -1: warm-up
    auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = process_cpu_ms();
    last = (*chain.value)->run(v, iso, -1024.0f);
    const double total = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (r >= 0) t_cpu.push_back(process_cpu_ms() - cpu0);
    n_active = last.stats.active;
    t0 = std::chrono::steady_clock::now();
    (void)engine::run_chain_cpu(v, p);
    const double dense = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    t0 = std::chrono::steady_clock::now();
    std::memcpy(f0.mapped(), v.voxels.data(), n * 4);
    const double in = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const double filters = floor_filters();
    const double dense_floor = floor_dense();
    const double fused = floor_fused();
    t0 = std::chrono::steady_clock::now();
    {
      std::vector<core::Sample> pool;
      pool.reserve(n_active * core::kBrickSamples);  // huge pages as publish_fill asks for them
      const std::uintptr_t huge = std::uintptr_t(2) << 20, p0 = reinterpret_cast<std::uintptr_t>(pool.data());
      const std::uintptr_t hb = (p0 + huge - 1) & ~(huge - 1), he = (p0 + pool.capacity() * 16) & ~(huge - 1);
      if (he > hb) (void)madvise(reinterpret_cast<void*>(hb), he - hb, MADV_HUGEPAGE);
      pool.resize(n_active * core::kBrickSamples);
      const auto* s = static_cast<const core::Sample*>(f1.mapped());  // any source of the same bytes
      for (std::size_t b = 0; b < n_active; ++b)
        std::memcpy(pool.data() + b * core::kBrickSamples, s + (b * core::kBrickSamples) % (n / 4 - core::kBrickSamples),
                    core::kBrickSamples * sizeof(core::Sample));
      EXPECT_EQ(pool.size(), n_active * core::kBrickSamples);
    }
    const double pub = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (r < 0) continue;
    double gpu = 0, host = 0;
    for (const auto& st : last.passes) (st.label.find("(GPU)") != std::string::npos ? gpu : host) += st.ms;
    t_total.push_back(total);
    t_dense.push_back(dense);
    t_in.push_back(in);
    t_filters.push_back(filters);
    t_dense_floor.push_back(dense_floor);
    t_fused.push_back(fused);
    t_pub.push_back(pub);
    t_gpu.push_back(gpu);
    t_host.push_back(host);
  }
  double load[3] = {0, 0, 0};
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf %lf %lf", &load[0], &load[1], &load[2]) != 3) load[0] = -1;
    std::fclose(f);
  }
  const double floor_sum = median(t_in) + median(t_fused) + median(t_pub);
  std::printf(
      "chest -500: %zu candidates, %zu active; lists: %.1f / %.1f / %.1f %% of the voxels; median of %d, load %.2f %.2f %.2f\n"
      "  dense CPU chain, one thread            %8.2f ms\n"
      "  lists strategy, total                  %8.2f ms  (GPU stages %.2f, host stages %.2f)  / dense CPU = %.3f\n"
      "  floor: input memcpy                    %8.2f ms\n"
      "  floor: fused pass, one tap per axis    %8.2f ms  (lavapipe, device time, %zu columns)\n"
      "  floor: 3 filter passes, one tap        %8.2f ms  (lavapipe, device time; dense, every voxel: %.2f ms)\n"
      "  floor: pool memcpy, fresh allocation   %8.2f ms  (%zu bricks)\n"
      "  floors summed                          %8.2f ms  / dense CPU = %.3f (the target: 0.333)\n",
      sel.candidates.size(), n_active, 100.0 * double(lists[0].quads) * 4 / double(n),
      100.0 * double(lists[1].quads) * 4 / double(n), 100.0 * double(lists[2].quads) * 4 / double(n), reps, load[0],
      load[1], load[2], median(t_dense), median(t_total), median(t_gpu), median(t_host),
      median(t_total) / median(t_dense), median(t_in), median(t_fused), columns.unit_count(), median(t_filters),
      median(t_dense_floor), median(t_pub), n_active, floor_sum,
      floor_sum / median(t_dense));
  for (const auto& st : last.passes) std::printf("    %-66s %8.2f ms\n", st.label.c_str(), st.ms);
  std::printf("  lists strategy, CPU time of all threads %8.2f ms (median)\n", median(t_cpu));
  std::printf("    %-66s %8.2f ms\n    %-66s %8.2f ms\n    %-66s %8.2f ms\n", "submit to fence (wall)",
              last.submit_wall_ms, "buffers + list upload (host)", last.upload_ms, "total (wall)", last.total_ms);
}

// The lists strategy's run split, on the head CT at +1150 and the chest CT at -500, the
// input imported (where the device offers it) and copied, ISOTOUCH_BENCH_REPS (default 50)
// runs each: min and median of the wall time, the host stages, the GPU stages (timestamps),
// the submit's wall time (what is none of these is set-up: buffers, recording) and of each
// stage. ISOTOUCH_SPLIT_CASE (e.g. "head +500") runs that case alone (perf).
//   test_sparse_chain --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_RunSplit*'
TEST(SparseChain, DISABLED_RunSplit) {
  const char* e = std::getenv("ISOTOUCH_BENCH_REPS");
  const int reps = e ? std::max(1, std::atoi(e)) : 50;
  const char* only = std::getenv("ISOTOUCH_SPLIT_CASE");
  const bool between = std::getenv("ISOTOUCH_SPLIT_BETWEEN") != nullptr;
  const std::vector<PassDesc> dense = {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax(1)};
  auto ctx = engine::VulkanContext::create({});  // no validation layer: timings
  ASSERT_TRUE(ctx) << ctx.error;
  auto chain = engine::SparseChain::create(**ctx.value, {PassDesc::gaussian(1.0), PassDesc::gradient()});
  ASSERT_TRUE(chain) << chain.error;
  const Volume head = io::load_volume(kHead), chest = io::load_volume(kChest);
  struct Case {
    const char* name;
    const Volume* v;
    double tau;
  };
  for (const Case& c : {Case{"head +1150", &head, 1150.0}, Case{"head +500", &head, 500.0}, Case{"chest -500", &chest, -500.0}})
  for (const bool import : {true, false}) {
    if (only && c.name != std::string(only)) continue;
    (*ctx.value)->allow_host_import(import);
    std::vector<double> total, stages, gpu, submit, cpu;
    std::map<std::string, std::vector<double>> by_stage;
    for (int r = -1; r < reps; ++r) {
      // ISOTOUCH_SPLIT_BETWEEN=1: the dense one-thread CPU chain between runs, as bench
      // engine runs it (caches and lavapipe's threads as that run leaves them).
      if (between) (void)engine::run_chain_cpu(*c.v, dense);
      rusage u0{}, u1{};
      getrusage(RUSAGE_SELF, &u0);
      const engine::SparseOutput out = (*chain.value)->run(*c.v, above(c.tau), -1024.0f);
      getrusage(RUSAGE_SELF, &u1);
      if (r < 0) continue;
      // CPU time of the whole process (lavapipe's threads included): the work of a run,
      // less sensitive than wall time to other processes on a shared machine.
      const auto ms = [](const rusage& u) {
        return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) * 1e3 +
               double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) / 1e3;
      };
      cpu.push_back(ms(u1) - ms(u0));
      for (const auto& p : out.passes) by_stage[p.label.substr(0, 40)].push_back(p.ms);
      double st = 0, g = 0;
      for (const auto& p : out.passes) (p.label.find("(GPU)") != std::string::npos ? g : st) += p.ms;
      total.push_back(out.total_ms);
      stages.push_back(st);
      gpu.push_back(g);
      submit.push_back(out.submit_wall_ms);
    }
    auto mm = [](std::vector<double> x) {
      std::sort(x.begin(), x.end());
      char b[64];
      std::snprintf(b, sizeof b, "%.3f / %.3f", x.front(), x[x.size() / 2]);
      return std::string(b);
    };
    double load = -1;
    if (FILE* f = std::fopen("/proc/loadavg", "r")) {
      if (std::fscanf(f, "%lf", &load) != 1) load = -1;
      std::fclose(f);
    }
    std::printf("%s, input %s, %d runs, load %.2f, min / median [ms]: total %s, host stages %s, GPU stages %s, "
                "submit wall %s, CPU time of all threads %s\n",
                c.name, import ? "imported where offered" : "copied", reps, load, mm(total).c_str(), mm(stages).c_str(),
                mm(gpu).c_str(), mm(submit).c_str(), mm(cpu).c_str());
    for (const auto& [label, ms] : by_stage) std::printf("    %-40s %s\n", label.c_str(), mm(ms).c_str());
  }
}

// The one-thread sparse CPU reference on the chest CT at -500 HU, its published pool fresh
// or recycled (PoolRecycler), alternating, ISOTOUCH_BENCH_REPS (default 8) runs each: min
// and median of the wall time and of the process's CPU time [ms].
//   test_sparse_chain --gtest_also_run_disabled_tests --gtest_filter='*DISABLED_CpuReferencePools*'
TEST(SparseChain, DISABLED_CpuReferencePools) {
  const char* e = std::getenv("ISOTOUCH_BENCH_REPS");
  const int reps = e ? std::max(1, std::atoi(e)) : 8;
  const Volume chest = io::load_volume(kChest);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  auto recycler = std::make_shared<engine::PoolRecycler>();
  const auto cpu_ms = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) * 1e3 + double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) / 1e3;
  };
  std::vector<double> wall[2], cpu[2];
  for (int r = -1; r < reps; ++r)
    for (int k = 0; k < 2; ++k) {
      const double c0 = cpu_ms();
      const auto t0 = std::chrono::steady_clock::now();
      (void)engine::run_sparse_cpu(chest, p, above(-500), -1024.0f, core::SampleFormat::kFp32, false, 1,
                                   k ? recycler : nullptr);
      if (r < 0) continue;
      wall[k].push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      cpu[k].push_back(cpu_ms() - c0);
    }
  for (int k = 0; k < 2; ++k) {
    for (auto* v : {&wall[k], &cpu[k]}) std::sort(v->begin(), v->end());
    std::printf("pool %s: wall min %.2f median %.2f, CPU min %.2f median %.2f [ms]\n", k ? "recycled" : "fresh",
                wall[k].front(), wall[k][wall[k].size() / 2], cpu[k].front(), cpu[k][cpu[k].size() / 2]);
  }
}
