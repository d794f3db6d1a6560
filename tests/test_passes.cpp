// Filter passes: every pass on the GPU against its CPU reference, with
// the validation layer on (synchronization validation too) and analytic truth from
// outside the code: Gaussian of a constant / ramp / delta, closing of a hole / plateau,
// brick min/max against brute force over the halo'd region.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <utility>

#include "isotouch/tests/vk_test_context.h"
#include "isotouch/tests/gpu_cpu_compare.h"
#include "isotouch/engine/cpu_filters.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/device_memory.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/engine/ulp.h"
#include "isotouch/engine/vk_resources.h"
#include "isotouch/io/volume_io.h"

using namespace isotouch;
using engine::PassDesc;
using engine::Volume;

namespace {
const std::string kData = ISOTOUCH_TEST_DATA;
const std::string kHead = kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
const std::string kChest = kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd";
const std::string kTooth = kData + "/ct-tooth/tooth.nhdr";

engine::VulkanContext& vk() { return test::validated_vk(); }

using engine::ulp_stats;
using engine::UlpStats;

std::vector<float> flatten(const core::SampleField& f) {
  std::vector<float> v;
  v.reserve(f.samples.size() * 4);
  for (const auto& s : f.samples) v.insert(v.end(), {s.value, s.gx, s.gy, s.gz});
  return v;
}

// The one rule (tests/gpu_cpu_compare.h): bit for bit on a CPU device (lavapipe: IEEE,
// `precise`, -ffp-contract=off), within a ULP bound on a GPU; the distribution is printed.
void expect_same(const std::vector<float>& gpu, const std::vector<float>& cpu, const std::string& what) {
  EXPECT_TRUE(isotouch::test::gpu_matches_cpu(vk(), gpu, cpu, what));
}

void expect_chain_matches_cpu_with(engine::ShaderSet shaders, const Volume& v, const std::vector<PassDesc>& passes,
                                   std::uint64_t max_binding, int min_dispatches) {
  auto chain = engine::PassChain::create(vk(), passes, shaders);
  ASSERT_TRUE(chain) << chain.error;
  const engine::ChainOutput g = (*chain.value)->run(v, max_binding);
  const engine::ChainOutput c = engine::run_chain_cpu(v, passes);
  std::string name = engine::shader_set_name(shaders);
  name += " ";
  name += v.path.substr(v.path.find_last_of('/') + 1);
  name += ":";
  for (const auto& p : passes) {
    name += ' ';
    name += p.label();
  }
  ASSERT_EQ(g.field.has_value(), c.field.has_value());
  ASSERT_EQ(g.samples.has_value(), c.samples.has_value());
  ASSERT_EQ(g.bricks.has_value(), c.bricks.has_value());
  if (c.field) expect_same(*g.field, *c.field, name + " field");
  if (c.samples) expect_same(flatten(*g.samples), flatten(*c.samples), name + " samples");
  if (c.bricks) {
    EXPECT_EQ(g.bricks->bricks, c.bricks->bricks);
    expect_same(g.bricks->min, c.bricks->min, name + " brick min");
    expect_same(g.bricks->max, c.bricks->max, name + " brick max");
  }
  int dispatches = 0;
  for (const auto& p : g.passes) dispatches += p.dispatches;
  EXPECT_GE(dispatches, min_dispatches) << (*chain.value)->describe();
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

// Both shader sets (the current texel-buffer x4 shaders and the legacy ones) against the CPU.
void expect_chain_matches_cpu(const Volume& v, const std::vector<PassDesc>& passes, std::uint64_t max_binding = 0,
                              int min_dispatches = 0) {
  expect_chain_matches_cpu_with(engine::ShaderSet::Current, v, passes, max_binding, min_dispatches);
  expect_chain_matches_cpu_with(engine::ShaderSet::Legacy, v, passes, max_binding, min_dispatches);
}

const std::vector<PassDesc> kFull = {PassDesc::gaussian(1.0), PassDesc::closing(2.0), PassDesc::gradient(),
                                     PassDesc::brick_minmax()};

// The GPU output of a single pass (the shipped path), for the analytic checks.
engine::ChainOutput gpu(const Volume& v, const std::vector<PassDesc>& passes) {
  auto chain = engine::PassChain::create(vk(), passes);
  if (!chain) throw std::runtime_error(chain.error);
  return (*chain.value)->run(v);
}

Volume constant(std::array<int, 3> dims, core::Vec3 spacing, float c) {
  Volume v = engine::make_random(dims, spacing, 0.0f, 1.0f, 1);
  std::fill(v.voxels.begin(), v.voxels.end(), c);
  v.update_stats();
  return v;
}

double g1(int k, double sigma) { return std::exp(-double(k) * k / (2 * sigma * sigma)); }
}  // namespace

// ---------------------------------------------------------------- GPU against CPU

TEST(PassesGpuVsCpu, HeadCt) {
  const Volume v = io::load_volume(kHead);
  expect_chain_matches_cpu(v, kFull);
  expect_chain_matches_cpu(v, {PassDesc::gaussian(2.5)});
  expect_chain_matches_cpu(v, {PassDesc::closing(4.0), PassDesc::brick_minmax(2)});
}

TEST(PassesGpuVsCpu, ChestCt) {
  const Volume v = io::load_volume(kChest);
  expect_chain_matches_cpu(v, kFull);
  // The scene: sigma 1 mm + gradient + min/max.
  expect_chain_matches_cpu(v, {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()});
}

TEST(PassesGpuVsCpu, WholeFieldGaussianAndGradientGiveTheSameBits) {
  // Rows of whole quads, radii <= ISOTOUCH_FUSED_MAX_RADIUS and the field in one binding: the
  // Gaussian runs as three whole-field passes (gauss_axis_x4) and the gradient as one
  // (gradient_whole_x4); radius 4 (sigma 1.2 voxels) is the widest they take, and a Gaussian
  // after a closing reads the closing's output. Truth: the CPU chain.
  const Volume v = engine::make_random({44, 37, 29}, {1e-3, 1e-3, 1e-3}, -50.0f, 50.0f, 7);
  for (const auto& p : {std::vector<PassDesc>{PassDesc::gaussian(1.2), PassDesc::gradient()},
                        std::vector<PassDesc>{PassDesc::closing(1.0), PassDesc::gaussian(0.6), PassDesc::gradient(),
                                              PassDesc::brick_minmax()}}) {
    auto chain = engine::PassChain::create(vk(), p);
    ASSERT_TRUE(chain) << chain.error;
    (void)(*chain.value)->run(v);
    EXPECT_NE((*chain.value)->describe().find("over the whole field (gauss_axis_x4"), std::string::npos)
        << (*chain.value)->describe();
    expect_chain_matches_cpu_with(engine::ShaderSet::Current, v, p, 0, 0);
  }
  // Radius 5 (sigma 1.5 voxels): the slab filters (filter_x4), the same bits.
  auto wide = engine::PassChain::create(vk(), {PassDesc::gaussian(1.5), PassDesc::gradient()});
  ASSERT_TRUE(wide) << wide.error;
  (void)(*wide.value)->run(v);
  EXPECT_EQ((*wide.value)->describe().find("gauss_axis_x4"), std::string::npos) << (*wide.value)->describe();
  expect_chain_matches_cpu_with(engine::ShaderSet::Current, v, {PassDesc::gaussian(1.5), PassDesc::gradient()}, 0, 0);
}

TEST(PassesGpuVsCpu, WholeFieldBrickMinMaxGivesTheSameBits) {
  // A brick min/max (halo 1) on rows of whole quads runs over the whole field: each slice's
  // brick row segments (minmax_segments) and a small reduction (minmax_slices). Sizes with a last brick of
  // one quad (nx % 8 == 4), partial bricks in y and z, one-brick and one-slice volumes; the
  // voxels hold +0 and -0 (the first of equal values wins in z, y, x order), NaN (skipped)
  // and ties, and the list without a Gaussian keeps them in the field. Truth: the CPU chain.
  // Also ramps along each axis both ways (every brick's extremes in its halo) and a field of
  // +0 / -0 only (the sign of the first zero in z, y, x order, the halo corner first).
  const std::vector<std::array<int, 3>> dims = {{44, 37, 29}, {16, 16, 16}, {4, 9, 3}, {8, 1, 1}, {12, 8, 2}};
  std::vector<Volume> volumes;
  std::uint32_t seed = 3;
  for (const auto& d : dims) {
    Volume v = engine::make_random(d, {0.8e-3, 1.1e-3, 2.0e-3}, -3.0f, 3.0f, seed++);
    std::uint32_t r = seed * 2654435761u;
    for (float& x : v.voxels) {
      r = r * 1664525u + 1013904223u;
      const std::uint32_t k = r >> 28;  // 16 cases
      if (k < 4) x = 0.0f;
      else if (k < 8) x = -0.0f;
      else if (k == 8) x = std::numeric_limits<float>::quiet_NaN();
      else if (k < 11) x = std::round(x);  // ties among the extremes
    }
    v.update_stats();
    volumes.push_back(std::move(v));
  }
  for (int axis = 0; axis < 6; ++axis) {
    Volume v = engine::make_random({28, 21, 19}, {1e-3, 1e-3, 1e-3}, 0.0f, 0.5f, 20u + std::uint32_t(axis));
    for (int z = 0; z < 19; ++z)
      for (int y = 0; y < 21; ++y)
        for (int x = 0; x < 28; ++x) {
          const int c[3] = {x, y, z};
          v.voxels[v.grid.index(x, y, z)] += float(axis % 2 ? -c[axis / 2] : c[axis / 2]);
        }
    v.update_stats();
    volumes.push_back(std::move(v));
  }
  {
    Volume v = engine::make_random({20, 19, 17}, {1e-3, 1e-3, 1e-3}, -1.0f, 1.0f, 31);
    for (float& x : v.voxels) x = x < 0 ? -0.0f : 0.0f;
    v.update_stats();
    volumes.push_back(std::move(v));
  }
  for (const Volume& v : volumes) {
    for (const auto& p : {std::vector<PassDesc>{PassDesc::gradient(), PassDesc::brick_minmax(1)},
                          std::vector<PassDesc>{PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax(1)},
                          std::vector<PassDesc>{PassDesc::brick_minmax(1), PassDesc::gradient()}}) {
      auto chain = engine::PassChain::create(vk(), p);
      ASSERT_TRUE(chain) << chain.error;
      (void)(*chain.value)->run(v);
      const std::string desc = (*chain.value)->describe();
      EXPECT_NE(desc.find("minmax_segments"), std::string::npos) << desc;
      expect_chain_matches_cpu_with(engine::ShaderSet::Current, v, p, 0, 0);
    }
  }
  // Halo 0 or rows not of whole quads: row ranges by slab (minmax_rows + minmax_bricks).
  const Volume odd = engine::make_random({37, 29, 23}, {0.7e-3, 1.1e-3, 2.3e-3}, -10.0f, 10.0f, 5);
  {
    auto chain = engine::PassChain::create(vk(), {PassDesc::gradient(), PassDesc::brick_minmax(0)});
    ASSERT_TRUE(chain) << chain.error;
    (void)(*chain.value)->run(engine::make_random({40, 16, 8}, {1e-3, 1e-3, 1e-3}, -1.0f, 1.0f, 9));
    EXPECT_NE((*chain.value)->describe().find("minmax_rows + minmax_bricks"), std::string::npos);
  }
  auto chain = engine::PassChain::create(vk(), {PassDesc::gradient(), PassDesc::brick_minmax(1)});
  ASSERT_TRUE(chain) << chain.error;
  (void)(*chain.value)->run(odd);
  EXPECT_NE((*chain.value)->describe().find("minmax_rows + minmax_bricks"), std::string::npos);
  expect_chain_matches_cpu_with(engine::ShaderSet::Current, odd, {PassDesc::gradient(), PassDesc::brick_minmax(1)}, 0, 0);
}

TEST(PassesGpuVsCpu, ToothInManySlabs) {
  // 4 MiB bindings: 103 x 94 x 161 floats are 6.2 MB, so every pass needs z-slabs, with
  // halos (z axis of the Gaussian, gradient, bricks) across the slab boundaries.
  const Volume v = io::load_volume(kTooth);
  expect_chain_matches_cpu(v, {PassDesc::gaussian(2.0), PassDesc::closing(2.0), PassDesc::gradient(),
                               PassDesc::brick_minmax()},
                           4u << 20, 2 * 9 + 2 + 2);  // >= 2 slabs for every dispatch step
}

TEST(PassesGpuVsCpu, SyntheticRandomOddSizes) {
  // NaN-free random data, sizes not a multiple of 8 (partial bricks), anisotropic spacing.
  const Volume v = engine::make_random({37, 29, 23}, {0.7e-3, 1.1e-3, 2.3e-3}, -1000.0f, 3000.0f, 42);
  expect_chain_matches_cpu(v, kFull);
  expect_chain_matches_cpu(v, {PassDesc::gaussian(3.0), PassDesc::closing(3.0), PassDesc::brick_minmax(0)},
                           64u << 10, 2 * 9 + 2);
}

TEST(PassesGpuVsCpu, ThinVolumesAndRowTails) {
  // Rows of 1, 2, 3, 5 and 9 voxels: the x4 shaders' lanes past the row's end, one-voxel
  // axes (gradient 0), one-sided borders on both sides of a 4-voxel group.
  const std::vector<std::array<int, 3>> dims = {{1, 5, 3}, {2, 1, 7}, {3, 4, 1}, {5, 3, 2}, {9, 1, 1}, {4, 4, 4}};
  std::uint32_t seed = 11;
  for (const auto& d : dims) {
    const Volume v = engine::make_random(d, {0.9e-3, 1.0e-3, 1.3e-3}, -100.0f, 100.0f, seed++);
    expect_chain_matches_cpu(v, {PassDesc::gaussian(1.0), PassDesc::gradient()});
    expect_chain_matches_cpu(v, {PassDesc::gradient()});
  }
}

TEST(PassesGpuVsCpu, GaussianRadiusAtAndAboveTheSpecialisedLimit) {
  // sigma 5.3 voxels: radius 16, the largest gaussian_x4 holds in specialization constants;
  // sigma 5.4: radius 17, which takes gaussian1d. Both against the CPU.
  const Volume v = engine::make_random({41, 37, 40}, {1e-3, 1e-3, 1e-3}, -50.0f, 50.0f, 5);
  EXPECT_EQ(engine::gaussian_kernel(5.3).size(), 33u);
  EXPECT_EQ(engine::gaussian_kernel(5.4).size(), 35u);
  expect_chain_matches_cpu(v, {PassDesc::gaussian(5.3)});
  expect_chain_matches_cpu(v, {PassDesc::gaussian(5.4)});
  auto chain = engine::PassChain::create(vk(), {PassDesc::gaussian(5.4)});
  ASSERT_TRUE(chain) << chain.error;
  (*chain.value)->run(v);
  EXPECT_NE((*chain.value)->describe().find("gaussian_x4 gaussian1d"), std::string::npos) << (*chain.value)->describe();
  // The closing's box: 16 voxels each side in filter_x4, 17 in morph1d.
  expect_chain_matches_cpu(v, {PassDesc::closing(16.0)});
  expect_chain_matches_cpu(v, {PassDesc::closing(17.0)});
  auto closing = engine::PassChain::create(vk(), {PassDesc::closing(17.0)});
  ASSERT_TRUE(closing) << closing.error;
  (*closing.value)->run(v);
  EXPECT_NE((*closing.value)->describe().find("morph_x4 morph1d"), std::string::npos) << (*closing.value)->describe();
}

TEST(PassesGpuVsCpu, ZeroCopyAndStagingGiveTheSameBits) {
  // lavapipe's one memory type is device-local, host-visible and coherent: the chain writes
  // the voxels and reads the outputs in place. With zero copy off it stages and reads back,
  // as on a discrete GPU; both against the CPU.
  const Volume v = engine::make_random({37, 29, 23}, {0.7e-3, 1.1e-3, 2.3e-3}, -1000.0f, 3000.0f, 43);
  if (isotouch::test::expects_bit_identity(vk())) {
    EXPECT_TRUE(vk().device_local_is_host_visible());
  }
  struct Restore {
    ~Restore() { vk().allow_zero_copy(true); }
  } restore;
  for (bool zero_copy : {true, false}) {
    vk().allow_zero_copy(zero_copy);
    auto chain = engine::PassChain::create(vk(), kFull);
    ASSERT_TRUE(chain) << chain.error;
    const std::string d = (*chain.value)->describe();
    const bool direct = vk().device_local_is_host_visible();
    EXPECT_EQ(d.find("no staging") != std::string::npos, direct) << d;
    EXPECT_EQ(d.find("+ readback") != std::string::npos, !direct) << d;
    expect_chain_matches_cpu(v, kFull, 64u << 10, 2 * 9 + 2);
    // Here the closing's last step (z, radius 0 at 2.3 mm spacing) copies its input, so
    // both ping-pong buffers hold the final field; a list ending on a Gaussian step does not.
    expect_chain_matches_cpu(v, {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()});
  }
}

// ---------------------------------------------------------------- analytic: Gaussian

TEST(CpuBackend, ThreadsGiveTheOneThreadReferenceBitForBit) {
  // The multi-threaded CPU backend (run_chain_cpu with threads > 1: every pass's rows split
  // among the threads) against the one-thread reference: every output bit for bit, on the
  // chest (a real volume) and an odd-sized random one (every border rule, parts of unequal
  // size: 389 slices over 2 and 3 threads; large enough for 3 threads by threads_for).
  const Volume chest = io::load_volume(kChest);
  const Volume odd = engine::make_random({67, 61, 389}, {0.7e-3, 1.1e-3, 2.3e-3}, -1000.0f, 3000.0f, 11);
  ASSERT_EQ(engine::threads_for(odd.grid.voxel_count(), 3), 3u);
  const std::vector<PassDesc> list = {PassDesc::closing(1.0), PassDesc::gaussian(1.0), PassDesc::gradient(),
                                      PassDesc::brick_minmax()};
  for (const Volume* v : {&chest, &odd}) {
    const engine::ChainOutput one = engine::run_chain_cpu(*v, list);
    for (unsigned threads : {2u, 3u}) {
      const auto t0 = std::chrono::steady_clock::now();
      const engine::ChainOutput many = engine::run_chain_cpu(*v, list, threads);
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      const std::string what = v->path + ", " + std::to_string(threads) + " threads";
      std::printf("  %s: %.1f ms (one thread: %.1f ms)\n", what.c_str(), ms, one.submit_wall_ms);
      ASSERT_TRUE(many.field && many.samples && many.bricks) << what;
      EXPECT_EQ(std::memcmp(many.field->data(), one.field->data(), one.field->size() * 4), 0) << what << ": field";
      EXPECT_EQ(std::memcmp(many.samples->samples.data(), one.samples->samples.data(),
                            one.samples->samples.size() * sizeof(core::Sample)),
                0)
          << what << ": samples";
      EXPECT_EQ(many.bricks->min, one.bricks->min) << what << ": brick minima";
      EXPECT_EQ(many.bricks->max, one.bricks->max) << what << ": brick maxima";
    }
  }
}

TEST(Gaussian, KernelIsNormalisedAndSymmetric) {
  for (double s : {0.3, 1.0, 2.7}) {
    const auto w = engine::gaussian_kernel(s);
    const int r = int(std::ceil(3 * s));
    ASSERT_EQ(w.size(), std::size_t(2 * r + 1));
    double sum = 0, norm = 0;
    for (int k = -r; k <= r; ++k) norm += g1(k, s);
    for (int k = -r; k <= r; ++k) {
      sum += w[std::size_t(k + r)];
      EXPECT_NEAR(w[std::size_t(k + r)], g1(k, s) / norm, 1e-7) << "sigma " << s << " k " << k;
      EXPECT_EQ(w[std::size_t(k + r)], w[std::size_t(r - k)]);
    }
    EXPECT_NEAR(sum, 1.0, 1e-6);
  }
  EXPECT_EQ(engine::gaussian_kernel(0.0), std::vector<float>{1.0f});
}

TEST(Gaussian, ConstantStaysConstant) {
  const Volume v = constant({19, 17, 13}, {1e-3, 1.3e-3, 2e-3}, 1234.5f);
  const auto out = gpu(v, {PassDesc::gaussian(1.5)});
  for (float f : *out.field) ASSERT_NEAR(f, 1234.5f, 1234.5f * 2e-6);  // weights sum to 1 within float rounding
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(Gaussian, RampStaysRampAwayFromBorders) {
  // value = 3 x + 5 y - 2 z (index units). A symmetric normalised kernel preserves a linear
  // function exactly wherever the window does not reach the border (clamp bends it there).
  const std::array<int, 3> d{24, 22, 26};
  const core::Vec3 h{1e-3, 1e-3, 1.5e-3};
  Volume v = constant(d, h, 0);
  for (int z = 0; z < d[2]; ++z)
    for (int y = 0; y < d[1]; ++y)
      for (int x = 0; x < d[0]; ++x) v.voxels[v.grid.index(x, y, z)] = float(3 * x + 5 * y - 2 * z);
  const double sigma_mm = 1.5;
  const auto out = gpu(v, {PassDesc::gaussian(sigma_mm)});
  const auto axes = engine::gaussian_axes(v.grid, sigma_mm);
  int r[3];
  for (int a = 0; a < 3; ++a) r[a] = int(axes.kernel[std::size_t(a)].size() / 2);
  int checked = 0;
  for (int z = r[2]; z < d[2] - r[2]; ++z)
    for (int y = r[1]; y < d[1] - r[1]; ++y)
      for (int x = r[0]; x < d[0] - r[0]; ++x, ++checked)
        ASSERT_NEAR((*out.field)[v.grid.index(x, y, z)], 3 * x + 5 * y - 2 * z, 2e-4) << x << " " << y << " " << z;
  EXPECT_GT(checked, 500);
  // ... and it does bend at the border (clamp to edge): the ramp is not preserved at x = 0.
  EXPECT_GT((*out.field)[v.grid.index(0, 11, 13)], float(3 * 0 + 5 * 11 - 2 * 13) + 0.1f);
}

TEST(Gaussian, DeltaGivesTheNormalisedKernel) {
  const std::array<int, 3> d{21, 21, 21};
  const core::Vec3 h{1e-3, 0.8e-3, 1.6e-3};
  Volume v = constant(d, h, 0);
  v.voxels[v.grid.index(10, 10, 10)] = 1.0f;
  const double sigma_mm = 1.6;
  const auto out = gpu(v, {PassDesc::gaussian(sigma_mm)});
  // Truth from the formula, not from gaussian_kernel(): product of 1-D normalised Gaussians.
  double s[3], norm[3];
  int r[3];
  for (int a = 0; a < 3; ++a) {
    s[a] = sigma_mm / (h[a] * 1e3);
    r[a] = int(std::ceil(3 * s[a]));
    norm[a] = 0;
    for (int k = -r[a]; k <= r[a]; ++k) norm[a] += g1(k, s[a]);
  }
  double total = 0;
  for (int z = 0; z < d[2]; ++z)
    for (int y = 0; y < d[1]; ++y)
      for (int x = 0; x < d[0]; ++x) {
        const int k[3] = {x - 10, y - 10, z - 10};
        double want = 1;
        for (int a = 0; a < 3; ++a) want *= std::abs(k[a]) <= r[a] ? g1(k[a], s[a]) / norm[a] : 0.0;
        const float got = (*out.field)[v.grid.index(x, y, z)];
        total += got;
        ASSERT_NEAR(got, want, 1e-6 * want + 1e-12) << x << " " << y << " " << z;
      }
  EXPECT_NEAR(total, 1.0, 1e-5);
}

// ---------------------------------------------------------------- analytic: closing

TEST(Closing, FillsASingleDarkVoxel) {
  Volume v = constant({15, 14, 13}, {1e-3, 1e-3, 1e-3}, 100.0f);
  v.voxels[v.grid.index(7, 6, 5)] = 0.0f;
  for (const auto& out : {gpu(v, {PassDesc::closing(1.0)}).field, engine::run_chain_cpu(v, {PassDesc::closing(1.0)}).field})
    for (float f : *out) ASSERT_EQ(f, 100.0f);
  // A radius smaller than a voxel is the identity: the hole stays.
  EXPECT_EQ((*gpu(v, {PassDesc::closing(0.4)}).field)[v.grid.index(7, 6, 5)], 0.0f);
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(Closing, LeavesABrightPlateau) {
  // A bright box on a dark background is closed under closing with a smaller box.
  Volume v = constant({20, 18, 16}, {1e-3, 1e-3, 1e-3}, -50.0f);
  for (int z = 4; z < 12; ++z)
    for (int y = 5; y < 13; ++y)
      for (int x = 3; x < 15; ++x) v.voxels[v.grid.index(x, y, z)] = 200.0f;
  const auto out = gpu(v, {PassDesc::closing(2.0)});
  EXPECT_EQ(*out.field, v.voxels);
}

TEST(Closing, FillsAGapNarrowerThanTheElement) {
  // Two plateaus separated by a 2-voxel dark slot: closing with radius 1 (box 3 wide)
  // fills it; radius 0 leaves it.
  Volume v = constant({16, 8, 8}, {1e-3, 1e-3, 1e-3}, 10.0f);
  for (int z = 0; z < 8; ++z)
    for (int y = 0; y < 8; ++y)
      for (int x = 7; x < 9; ++x) v.voxels[v.grid.index(x, y, z)] = 0.0f;
  const auto closed = gpu(v, {PassDesc::closing(1.0)});
  for (float f : *closed.field) ASSERT_EQ(f, 10.0f);
  EXPECT_EQ(*gpu(v, {PassDesc::closing(0.5)}).field, v.voxels);
}

// ---------------------------------------------------------------- brick min/max

TEST(BrickMinMax, EqualsBruteForceOverTheHaloedBrick) {
  const Volume v = engine::make_random({27, 19, 17}, {1e-3, 1e-3, 1e-3}, -5.0f, 5.0f, 7);
  for (int halo : {0, 1, 3}) {
    const auto out = gpu(v, {PassDesc::brick_minmax(halo)});
    const auto& b = *out.bricks;
    ASSERT_EQ(b.bricks, (std::array<int, 3>{4, 3, 3}));
    std::size_t i = 0;
    for (int bz = 0; bz < 3; ++bz)
      for (int by = 0; by < 3; ++by)
        for (int bx = 0; bx < 4; ++bx, ++i) {
          float mn = std::numeric_limits<float>::max(), mx = -mn;
          for (int z = bz * 8 - halo; z <= bz * 8 + 7 + halo; ++z)
            for (int y = by * 8 - halo; y <= by * 8 + 7 + halo; ++y)
              for (int x = bx * 8 - halo; x <= bx * 8 + 7 + halo; ++x) {
                if (x < 0 || y < 0 || z < 0 || x >= 27 || y >= 19 || z >= 17) continue;
                mn = std::min(mn, v.voxels[v.grid.index(x, y, z)]);
                mx = std::max(mx, v.voxels[v.grid.index(x, y, z)]);
              }
          ASSERT_EQ(b.min[i], mn) << "brick " << bx << " " << by << " " << bz << " halo " << halo;
          ASSERT_EQ(b.max[i], mx) << "brick " << bx << " " << by << " " << bz << " halo " << halo;
        }
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(BrickMinMax, HaloSeesTheNeighbourVoxel) {
  // One spike at x = 8 (first voxel of brick 1): with halo 1 brick 0 must see it too.
  Volume v = constant({16, 8, 8}, {1e-3, 1e-3, 1e-3}, 0.0f);
  v.voxels[v.grid.index(8, 3, 3)] = 1000.0f;
  const auto b = *gpu(v, {PassDesc::brick_minmax(1)}).bricks;
  EXPECT_EQ(b.max[0], 1000.0f);
  EXPECT_EQ(b.max[1], 1000.0f);
  const auto b0 = *gpu(v, {PassDesc::brick_minmax(0)}).bricks;
  EXPECT_EQ(b0.max[0], 0.0f);
}

// ---------------------------------------------------------------- the chain and the layer

TEST(PassChain, CreatesOnlyWhatTheListNeedsAndSaysSo) {
  auto chain = engine::PassChain::create(vk(), {PassDesc::gaussian(1.0), PassDesc::brick_minmax()});
  ASSERT_TRUE(chain) << chain.error;
  const std::string d = (*chain.value)->describe();
  EXPECT_NE(d.find("pipelines created: gaussian_x4 brick_minmax"), std::string::npos) << d;
  EXPECT_NE(d.find("left out (not created, not run): morph_x4 morph1d gradient"), std::string::npos) << d;
  EXPECT_NE(d.find("samples (16 B/voxel)"), std::string::npos) << d;
  const auto out = (*chain.value)->run(engine::make_random({9, 9, 9}, {1e-3, 1e-3, 1e-3}, 0, 1, 3));
  EXPECT_TRUE(out.field && out.bricks);
  EXPECT_FALSE(out.samples);
  ASSERT_EQ(out.passes.size(), 2u);
  EXPECT_NE((*chain.value)->describe().find("last run:"), std::string::npos);
}

TEST(PassChain, BadListsAreClearErrors) {
  auto e1 = engine::PassChain::create(vk(), {});
  EXPECT_FALSE(e1);
  EXPECT_NE(e1.error.find("empty"), std::string::npos);
  auto e2 = engine::PassChain::create(vk(), {PassDesc::gaussian(-1.0)});
  EXPECT_NE(e2.error.find("sigma_mm"), std::string::npos) << e2.error;
  auto e3 = engine::PassChain::create(vk(), {PassDesc::gradient(), PassDesc::gradient()});
  EXPECT_NE(e3.error.find("once"), std::string::npos) << e3.error;
  // A kernel wider than kMaxFilterRadius is rejected at run time, naming the volume.
  auto c = engine::PassChain::create(vk(), {PassDesc::gaussian(500.0)});
  ASSERT_TRUE(c);
  try {
    (*c.value)->run(engine::make_random({8, 8, 8}, {1e-3, 1e-3, 1e-3}, 0, 1, 3));
    FAIL() << "expected VolumeError";
  } catch (const engine::VolumeError& e) {
    EXPECT_NE(std::string(e.what()).find("synthetic"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("exceeds"), std::string::npos) << e.what();
  }
}

TEST(VulkanLayer, SliceLargerThanABindingIsAClearError) {
  // 40 x 40 floats = 6400 bytes per slice against a 4 KiB binding limit.
  const Volume v = engine::make_random({40, 40, 9}, {1e-3, 1e-3, 1e-3}, 0, 1, 5);
  auto c = engine::PassChain::create(vk(), {PassDesc::gaussian(1.0)});
  ASSERT_TRUE(c);
  try {
    (*c.value)->run(v, 4096);
    FAIL() << "expected VolumeError";
  } catch (const engine::VolumeError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("synthetic"), std::string::npos) << m;
    EXPECT_NE(m.find("6400 bytes"), std::string::npos) << m;
    EXPECT_NE(m.find("storage-buffer binding of 4096 bytes"), std::string::npos) << m;
  }
}

TEST(VulkanLayer, AllocationLargerThanTheDeviceAllowsIsAClearError) {
  const VkDeviceSize too_big = vk().max_allocation_bytes() + 1;
  auto r = engine::GpuBuffer::create(vk(), too_big, engine::MemoryIntent::DeviceLocal, "test");
  ASSERT_FALSE(r);
  EXPECT_NE(r.error.find(std::to_string(too_big)), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("maxMemoryAllocationSize " + std::to_string(vk().max_allocation_bytes())), std::string::npos)
      << r.error;
  auto ok = engine::GpuBuffer::create(vk(), 1024, engine::MemoryIntent::Readback, "small");
  ASSERT_TRUE(ok) << ok.error;
  EXPECT_NE(ok.value->mapped(), nullptr);
  auto dev = engine::GpuBuffer::create(vk(), 1024, engine::MemoryIntent::DeviceLocal, "small");
  ASSERT_TRUE(dev) << dev.error;
  // Device-local buffers are mapped exactly where device-local memory is host-visible (zero copy).
  EXPECT_EQ(dev.value->mapped() != nullptr, vk().device_local_is_host_visible());
  vk().allow_zero_copy(false);
  auto staged = engine::GpuBuffer::create(vk(), 1024, engine::MemoryIntent::DeviceLocal, "small");
  vk().allow_zero_copy(true);
  ASSERT_TRUE(staged) << staged.error;
  EXPECT_EQ(staged.value->mapped(), nullptr) << "with zero copy off, device-local buffers are not mapped";
}

// ---------------------------------------------------------------- timings (printed)

TEST(PassesTiming, GpuVsOneThreadCpuOnHeadAndChest) {
  // One run each, printed for the report (not asserted: machine-dependent). A context of
  // its own without the validation layer, which would time itself too.
  auto plain = engine::VulkanContext::create();
  ASSERT_TRUE(plain) << plain.error;
  engine::VulkanContext& ctx = **plain.value;
  std::printf("device: %s (%s)\n", ctx.info().name.c_str(), ctx.info().type.c_str());
  // The full chain on both volumes, then the chest scene (sigma 1 mm + gradient + min/max).
  const std::vector<PassDesc> scene = {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()};
  for (const auto& [path, list] : {std::pair{kHead, kFull}, std::pair{kChest, kFull}, std::pair{kChest, scene}}) {
    const Volume v = io::load_volume(path);
    const auto chain = engine::PassChain::create(ctx, list);
    ASSERT_TRUE(chain);
    (*chain.value)->run(v);  // warm-up (pipeline compilation in the driver, page faults)
    const auto g = (*chain.value)->run(v);
    const auto c = engine::run_chain_cpu(v, list);
    std::printf("%s %dx%dx%d\n", path.substr(path.find_last_of('/') + 1).c_str(), v.grid.dims[0], v.grid.dims[1],
                v.grid.dims[2]);
    for (std::size_t i = 0; i < g.passes.size(); ++i)
      std::printf("  %-26s GPU %8.2f ms  CPU(1 thread) %8.2f ms  ratio CPU/GPU %5.2f\n", g.passes[i].label.c_str(),
                  g.passes[i].ms, c.passes[i].ms, g.passes[i].ms > 0 ? c.passes[i].ms / g.passes[i].ms : 0.0);
    std::printf("  GPU submit->fence %.2f ms, upload %.2f ms, download %.2f ms; CPU total %.2f ms\n", g.submit_wall_ms,
                g.upload_ms, g.download_ms, c.submit_wall_ms);
    std::printf("%s\n", (*chain.value)->describe().c_str());
  }
  EXPECT_EQ(vk().validation_messages(), 0u);
}

TEST(PassesTiming, DISABLED_ChestSceneMedians) {
  // The chest scene's dense chain (sigma 1 mm + gradient + brick min/max), 15 runs after a
  // warm-up, median device time per pass and of the sum: for comparing builds quickly.
  auto plain = engine::VulkanContext::create();
  ASSERT_TRUE(plain) << plain.error;
  const std::vector<PassDesc> scene = {PassDesc::gaussian(1.0), PassDesc::gradient(), PassDesc::brick_minmax()};
  const Volume v = io::load_volume(kChest);
  const auto chain = engine::PassChain::create(**plain.value, scene);
  ASSERT_TRUE(chain);
  (*chain.value)->run(v);
  std::vector<std::vector<double>> ms(scene.size() + 1);
  for (int r = 0; r < 15; ++r) {
    const auto g = (*chain.value)->run(v);
    double sum = 0;
    for (std::size_t i = 0; i < g.passes.size(); ++i) {
      ms[i].push_back(g.passes[i].ms);
      sum += g.passes[i].ms;
    }
    ms.back().push_back(sum);
  }
  for (std::size_t i = 0; i < ms.size(); ++i) {
    std::sort(ms[i].begin(), ms[i].end());
    std::printf("%s %.2f ms\n", i < scene.size() ? scene[i].label().c_str() : "sum", ms[i][ms[i].size() / 2]);
  }
}

// The device memory a process prints (isotouch-sculpt --stats): what its buffers hold while
// they live, back to where it was once they are freed; the peak keeps the most.
TEST(DeviceMemory, CountsWhatGpuBuffersHoldWhileTheyLive) {
  const engine::DeviceMemoryUse before = engine::device_memory_use();
  {
    auto a = engine::GpuBuffer::create(vk(), 3u << 20, engine::MemoryIntent::DeviceLocal, "counted 3 MiB");
    auto b = engine::GpuBuffer::create(vk(), 1u << 20, engine::MemoryIntent::Upload, "counted 1 MiB");
    ASSERT_TRUE(a && b);
    const engine::DeviceMemoryUse during = engine::device_memory_use();
    EXPECT_GE(during.live_bytes, before.live_bytes + (4u << 20));
    EXPECT_LE(during.live_bytes, before.live_bytes + (4u << 20) + (1u << 16)) << "more than the buffers and their alignment";
    EXPECT_EQ(during.allocations, before.allocations + 2);
    EXPECT_GE(during.peak_bytes, during.live_bytes);
    EXPECT_NE(engine::memory_report().find("device memory " + std::to_string(std::lround(double(during.live_bytes) / (1 << 20))) + " MiB now"), std::string::npos)
        << engine::memory_report();
  }
  const engine::DeviceMemoryUse after = engine::device_memory_use();
  EXPECT_EQ(after.live_bytes, before.live_bytes);
  EXPECT_EQ(after.allocations, before.allocations);
  EXPECT_GE(after.peak_bytes, before.live_bytes + (4u << 20));
}
