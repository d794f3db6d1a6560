// The engine's CPU code without Vulkan (target isotouch::engine_cpu: the ThreadSanitizer
// preset builds and runs this): the multi-threaded dense and sparse CPU backends give their
// one-thread references bit for bit. Truth from outside the threaded code: the one-thread
// references (themselves checked against brute force and the GPU in test_passes and
// test_sparse_chain), on synthetic volumes.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <string>

#include "isotouch/engine/parallel.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/sparse_chain.h"
#include "isotouch/engine/synthetic.h"

namespace engine = isotouch::engine;
namespace core = isotouch::core;
using engine::PassDesc;

namespace {
bool same_sample(const core::Sample& a, const core::Sample& b) { return std::memcmp(&a, &b, sizeof a) == 0; }

core::Isosurface above(double tau) { return core::Isosurface{tau, core::InsideIs::kAbove}; }

template <class A, class B>  // std::vector<core::Sample> or core::SamplePool
std::size_t differing_samples(const A& a, const B& b) {
  if (a.size() != b.size()) return std::max(a.size(), b.size());
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.size(); ++i) n += !same_sample(a[i], b[i]);
  return n;
}
}  // namespace

TEST(CpuBackends, DenseChainThreadsGiveTheReferenceBitForBit) {
  // Large enough that 2 and 3 threads are started (engine::threads_for: one per 2^19 voxels).
  const engine::Volume v = engine::make_random({128, 128, 97}, {0.9e-3, 1.1e-3, 1.7e-3}, -1000.0f, 3000.0f, 11);
  ASSERT_EQ(engine::threads_for(v.grid.voxel_count(), 3), 3u);
  const std::vector<PassDesc> p = {PassDesc::closing(1.0), PassDesc::gaussian(1.0), PassDesc::gradient(),
                                   PassDesc::brick_minmax()};
  const engine::ChainOutput one = engine::run_chain_cpu(v, p, 1);
  ASSERT_TRUE(one.samples && one.field && one.bricks);
  for (unsigned threads : {2u, 3u}) {
    const engine::ChainOutput many = engine::run_chain_cpu(v, p, threads);
    ASSERT_TRUE(many.samples && many.field && many.bricks);
    EXPECT_EQ(differing_samples(one.samples->samples, many.samples->samples), 0u) << threads << " threads";
    ASSERT_EQ(one.field->size(), many.field->size());
    EXPECT_EQ(std::memcmp(one.field->data(), many.field->data(), one.field->size() * sizeof(float)), 0)
        << threads << " threads: filtered field";
  }
}

// The cancel flag: unset, the run is the reference bit for bit; set, the run stops with
// ChainCancelled naming where, and returns nothing.
TEST(CpuBackends, ACancelledChainStopsWithChainCancelled) {
  const engine::Volume v = engine::make_random({40, 36, 30}, {1e-3, 1e-3, 2e-3}, -1000.0f, 3000.0f, 5);
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::closing(1.0), PassDesc::gradient()};
  std::atomic<bool> cancel{false};
  const engine::ChainOutput ref = engine::run_chain_cpu(v, p, 1);
  const engine::ChainOutput with_flag = engine::run_chain_cpu(v, p, 1, &cancel);
  ASSERT_TRUE(ref.samples && with_flag.samples);
  EXPECT_EQ(differing_samples(ref.samples->samples, with_flag.samples->samples), 0u);
  cancel = true;
  try {
    engine::run_chain_cpu(v, p, 2, &cancel);
    ADD_FAILURE() << "a cancelled chain returned";
  } catch (const engine::ChainCancelled& e) {
    EXPECT_STREQ(e.what(), "pass chain cancelled before gaussian(sigma 1 mm)") << "the first pass does not start";
  }
}

TEST(CpuBackends, SparseChainThreadsGiveTheReferenceBitForBit) {
  // A sphere filling most of the grid: enough candidate work for 2 and 3 threads.
  const engine::Volume v = engine::make_sphere({160, 150, 140}, 1e-3, 66.0, {0.7, -1.3, 0.4});
  const std::vector<PassDesc> p = {PassDesc::gaussian(1.0), PassDesc::gradient()};
  const engine::SparseOutput one = engine::run_sparse_cpu(v, p, above(0), -1e4f, core::SampleFormat::kFp32, true);
  ASSERT_GT(one.stats.active, 0u);
  // Candidates x their 17^3-voxel raw regions must reach 3 x 2^19 voxels for 3 threads.
  ASSERT_GT(one.stats.candidates * 17u * 17u * 17u, 3u * engine::kMinVoxelsPerThread);
  for (unsigned threads : {2u, 3u}) {
    const engine::SparseOutput many =
        engine::run_sparse_cpu(v, p, above(0), -1e4f, core::SampleFormat::kFp32, true, threads);
    EXPECT_EQ(one.stats.candidates, many.stats.candidates) << threads << " threads";
    EXPECT_EQ(one.input.active, many.input.active) << threads << " threads";
    EXPECT_EQ(differing_samples(one.input.pool, many.input.pool), 0u) << threads << " threads: pool samples";
  }
}
