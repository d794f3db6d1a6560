// bench engine: the computing parts of `isotouch bench engine` against
// independent computations: peak RSS of children that allocate a known amount (fork, and
// coreutils dd through exec), the minimum-bytes formula from the sample layout, ratios and
// percents recomputed from a row's own columns, brick counts from ceil(dims / 8), the active
// bricks from the dense CPU reference's brick min/max, snapshot bytes bounded below by the
// active bricks' samples, and verdicts that flip where the figure crosses the target.
// No timed assertions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <vector>

#include "isotouch/bench/bench_engine.h"
#include "isotouch/engine/cpu_filters.h"
#include "isotouch/engine/synthetic.h"

using namespace isotouch;
using bench::kNaN;

namespace {
constexpr std::uint64_t kMiB = 1024 * 1024;

// Touch every page of a fresh allocation so it is resident.
int allocate_and_touch(std::size_t bytes) {
  std::vector<unsigned char> v(bytes);
  for (std::size_t i = 0; i < bytes; i += 4096) v[i] = static_cast<unsigned char>(i >> 12);
  volatile unsigned char sink = v[bytes / 3];
  (void)sink;
  return 0;
}
}  // namespace

// --- child processes first, while this test process is small --------------------------

TEST(BenchEngineChild, ForkPeakRssCoversWhatTheChildAllocated) {
  const std::size_t bytes = 300 * kMiB;
  const bench::ChildRun r = bench::run_child_fork([&] { return allocate_and_touch(bytes); });
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_GE(r.peak_rss_bytes, bytes);
  // and not absurdly more: the child's 300 MiB plus this small test process
  EXPECT_LT(r.peak_rss_bytes, bytes + 1024 * kMiB);
}

TEST(BenchEngineChild, ForkPassesExitCodeAndStdout) {
  const bench::ChildRun r = bench::run_child_fork([] {
    std::printf("alpha=1\nbeta=two words\nnot a pair\n");
    return 7;
  });
  ASSERT_TRUE(r.started) << r.error;
  EXPECT_EQ(r.exit_code, 7);
  const auto kv = bench::parse_key_values(r.out);
  ASSERT_EQ(kv.size(), 2u) << r.out;
  EXPECT_EQ(kv.at("alpha"), "1");
  EXPECT_EQ(kv.at("beta"), "two words");
}

TEST(BenchEngineChild, ExecPeakRssOfDdBuffer) {
  // coreutils dd allocates one buffer of bs bytes and reads /dev/zero into it: resident.
  const bench::ChildRun r =
      bench::run_child_exec({"/bin/dd", "if=/dev/zero", "of=/dev/null", "bs=200M", "count=1", "status=none"});
  ASSERT_TRUE(r.started) << r.error;
  ASSERT_EQ(r.exit_code, 0) << r.error;
  EXPECT_GE(r.peak_rss_bytes, 200 * kMiB);
}

TEST(BenchEngineChild, ExecReportsExitCodeSignalAndMissingProgram) {
  const bench::ChildRun a = bench::run_child_exec({"/bin/sh", "-c", "echo k=v; exit 3"});
  EXPECT_EQ(a.exit_code, 3);
  EXPECT_EQ(bench::parse_key_values(a.out).at("k"), "v");
  const bench::ChildRun b = bench::run_child_exec({"/bin/sh", "-c", "kill -9 $$"});
  EXPECT_EQ(b.signal, 9);
  EXPECT_EQ(b.exit_code, -1);
  const bench::ChildRun c = bench::run_child_exec({"/no/such/program"});
  EXPECT_EQ(c.exit_code, 127);
  EXPECT_NE(c.error.find("/no/such/program"), std::string::npos);
}

TEST(BenchEngineChild, SelfPeakRssAtLeastAnAllocation) {
  allocate_and_touch(64 * kMiB);
  EXPECT_GE(bench::self_peak_rss_bytes(), 64 * kMiB);
}

// --- formulas ---------------------------------------------------------------------------

TEST(BenchEngineFormula, MinimumBytesFromTheSampleLayout) {
  const std::uint64_t n = 1000, b = 7;
  const std::uint64_t f = sizeof(float), sample = 4 * sizeof(float);  // GLSL vec4(value, gx, gy, gz)
  EXPECT_EQ(bench::pass_min_bytes(engine::PassKind::Gaussian, n, b), n * f + n * f);
  EXPECT_EQ(bench::pass_min_bytes(engine::PassKind::Closing, n, b), n * f + n * f);
  EXPECT_EQ(bench::pass_min_bytes(engine::PassKind::Gradient, n, b), n * f + n * sample);
  EXPECT_EQ(bench::pass_min_bytes(engine::PassKind::BrickMinMax, n, b), n * f + b * 2 * f);
}

TEST(BenchEngineFormula, BandwidthMedianRatio) {
  EXPECT_DOUBLE_EQ(bench::gb_per_s(2e9, 1000.0), 2.0);  // 2e9 B in 1 s
  EXPECT_DOUBLE_EQ(bench::gb_per_s(5e6, 1.0), 5.0);     // 5e6 B in 1 ms
  EXPECT_TRUE(std::isnan(bench::gb_per_s(1e9, 0.0)));
  EXPECT_TRUE(std::isnan(bench::gb_per_s(1e9, kNaN)));
  EXPECT_DOUBLE_EQ(eval::median({3, 1, 2}), 2.0);
  EXPECT_DOUBLE_EQ(eval::median({4, 1, 3, 2}), 2.5);
  EXPECT_DOUBLE_EQ(eval::median({kNaN, 5, kNaN}), 5.0);
  EXPECT_TRUE(std::isnan(eval::median({})));
  EXPECT_DOUBLE_EQ(bench::ratio(1, 4), 0.25);
  EXPECT_TRUE(std::isnan(bench::ratio(1, 0)));
  EXPECT_TRUE(std::isnan(bench::ratio(kNaN, 1)));
}

TEST(BenchEngineFormula, MemcpyBandwidthIsPositive) {
  const double g = bench::measure_memcpy_gbps(8 * kMiB, 2);
  EXPECT_TRUE(std::isfinite(g));
  EXPECT_GT(g, 0.0);
}

// --- verdicts -----------------------------------------------------------------------------

TEST(BenchEngineVerdict, FlipsWhereTheFigureCrossesTheTarget) {
  const double t = 1.0 / 3.0;
  const bench::Verdict below = bench::verdict_at_most("chest -500 sparse GPU / dense CPU", 0.20, t, 2);
  EXPECT_TRUE(below.measured);
  EXPECT_TRUE(below.met);
  EXPECT_EQ(below.text, "chest -500 sparse GPU / dense CPU = 0.20: target <= 0.33 met");
  const bench::Verdict above = bench::verdict_at_most("chest -500 sparse GPU / dense CPU", 0.40, t, 2);
  EXPECT_TRUE(above.measured);
  EXPECT_FALSE(above.met);
  EXPECT_EQ(above.text, "chest -500 sparse GPU / dense CPU = 0.40: target <= 0.33 NOT met");
  // Either side of the target by one ULP, and at it.
  EXPECT_TRUE(bench::verdict_at_most("x", t, t).met);
  EXPECT_FALSE(bench::verdict_at_most("x", std::nextafter(t, 1.0), t).met);
  EXPECT_TRUE(bench::verdict_at_most("x", std::nextafter(t, 0.0), t).met);
  const bench::Verdict none = bench::verdict_at_most("bytes", kNaN, 0.15, 2, "sparse: not available");
  EXPECT_FALSE(none.measured);
  EXPECT_FALSE(none.met);
  EXPECT_NE(none.text.find("not measured (sparse: not available)"), std::string::npos) << none.text;
}

// --- the synthetic volume -----------------------------------------------------------------

TEST(BenchEngineVolume, NoisySphereIsTheSphereWithinTheNoise) {
  const int n = 24;
  const engine::Volume a = bench::make_noisy_sphere(n, 1e-3, 1.0, 5);
  const engine::Volume b = engine::make_sphere({n, n, n}, 1e-3, 0.375 * n);
  ASSERT_EQ(a.voxels.size(), b.voxels.size());
  double sum = 0, maxabs = 0;
  for (std::size_t i = 0; i < a.voxels.size(); ++i) {
    const double d = double(a.voxels[i]) - double(b.voxels[i]);
    sum += d;
    maxabs = std::max(maxabs, std::abs(d));
  }
  EXPECT_LE(maxabs, 1.0 + 1e-4);
  EXPECT_GT(maxabs, 0.9);  // noise is there
  EXPECT_LT(std::abs(sum / double(a.voxels.size())), 0.05);  // zero mean (uniform, 13824 draws)
  const engine::Volume c = bench::make_noisy_sphere(n, 1e-3, 1.0, 5);
  EXPECT_EQ(a.voxels, c.voxels);  // reproducible
}

// --- one case on a small volume -------------------------------------------------------------

namespace {
engine::VulkanContext* vk(std::string& why) {
  static std::unique_ptr<engine::VulkanContext> ctx;
  static std::string err;
  static bool tried = false;
  if (!tried) {
    tried = true;
    auto r = engine::VulkanContext::create();
    if (r) ctx = std::move(*r.value);
    else err = r.error;
  }
  why = err;
  return ctx.get();
}

// Bytes per sample of a format (core/brick_field.h).
std::uint64_t sample_bytes(core::SampleFormat f) { return f == core::SampleFormat::kFp32 ? 16 : 8; }
}  // namespace

TEST(BenchEngineCase, RowOnASmallSphereAgainstIndependentFigures) {
  const int n = 40;  // 5^3 bricks
  const engine::Volume v = bench::make_noisy_sphere(n, 1e-3, 1.0, 3);
  const core::Isosurface iso{0.0, core::InsideIs::kAbove};
  bench::BenchCase c{"small", v.path, &v, {iso}};
  std::string why;
  engine::VulkanContext* ctx = vk(why);
  // Every machine this runs on has a Vulkan device (lavapipe at least): no device is a failure.
  ASSERT_NE(ctx, nullptr) << "no Vulkan device: " << why;
  std::ostringstream progress;
  const double memcpy_gbps = 10.0;
  const bench::CaseResult r = bench::run_case(ctx, why, c, false, 2, memcpy_gbps, progress);
  EXPECT_NE(progress.str().find("repetition 2/2"), std::string::npos);

  const std::uint64_t nb = 5 * 5 * 5, nv = std::uint64_t(n) * n * n;
  EXPECT_EQ(r.bricks, nb);
  EXPECT_EQ(r.voxels, nv);
  ASSERT_EQ(r.passes.size(), 3u);  // gaussian, gradient, brick_minmax
  const std::uint64_t want_bytes[3] = {8 * nv, 20 * nv, 4 * nv + 8 * nb};
  std::uint64_t bytes_sum = 0;
  double cpu_sum = 0, gpu_sum = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const bench::PassRow& p = r.passes[i];
    EXPECT_EQ(p.min_bytes, want_bytes[i]) << p.label;
    ASSERT_TRUE(std::isfinite(p.cpu_ms) && p.cpu_ms >= 0) << p.label;
    // derived columns recomputed from the row's own columns
    EXPECT_NEAR(p.cpu_gbps, double(p.min_bytes) / (p.cpu_ms * 1e6), 1e-9 * p.cpu_gbps) << p.label;
    EXPECT_NEAR(p.cpu_of_memcpy, p.cpu_gbps / memcpy_gbps, 1e-12) << p.label;
    if (ctx && std::isfinite(p.gpu_ms)) {
      EXPECT_NEAR(p.gpu_gbps, double(p.min_bytes) / (p.gpu_ms * 1e6), 1e-9 * p.gpu_gbps) << p.label;
      EXPECT_NEAR(p.gpu_of_memcpy, p.gpu_gbps / memcpy_gbps, 1e-12) << p.label;
      EXPECT_NEAR(p.gpu_over_cpu, p.gpu_ms / p.cpu_ms, 1e-12 * p.gpu_over_cpu) << p.label;
    }
    bytes_sum += p.min_bytes;
    cpu_sum += p.cpu_ms;
    gpu_sum += p.gpu_ms;
  }
  EXPECT_EQ(r.sum.min_bytes, bytes_sum);
  EXPECT_NEAR(r.sum.cpu_ms, cpu_sum, 1e-9);
  EXPECT_TRUE(std::isfinite(r.dense_cpu_wall_ms));
  if (ctx) {
    EXPECT_TRUE(r.gpu_available) << r.gpu_why;
    EXPECT_TRUE(std::isfinite(r.dense_gpu_wall_ms));
    EXPECT_NEAR(r.dense_gpu_over_cpu_wall, r.dense_gpu_wall_ms / r.dense_cpu_wall_ms, 1e-12);
    if (std::isfinite(gpu_sum)) {
      EXPECT_NEAR(r.sum.gpu_ms, gpu_sum, 1e-9);
    }
  }
  // The standalone pass set, timed in the same repetitions: every output the CPU chain's bits,
  // the best set the Gaussian + gradient + the faster brick min/max, the chain's ratio to it.
  if (ctx) {
    const bench::StandaloneFigures& sf = r.standalone;
    ASSERT_TRUE(sf.why.empty()) << sf.why;
    ASSERT_EQ(sf.rows.size(), 4u);
    EXPECT_TRUE(sf.all_same_bits);
    for (const auto& row : sf.rows) EXPECT_TRUE(row.same_bits && row.ms > 0) << row.label;
    EXPECT_DOUBLE_EQ(sf.best_set_ms, sf.rows[0].ms + sf.rows[1].ms + std::min(sf.rows[2].ms, sf.rows[3].ms));
    // Every timed set run paired with a chain run beside it; the ratio their median.
    ASSERT_EQ(sf.set_ms_per_run.size(), r.chain_pair_ms.size());
    ASSERT_FALSE(r.chain_pair_ms.empty());
    const bool rows = sf.rows[2].ms <= sf.rows[3].ms;
    std::vector<double> ratios;
    // The brick min/max forms take turns right after the gradient: the best form's time in
    // every other run, NaN in the rest.
    std::size_t timed = 0;
    for (std::size_t i = 0; i < r.chain_pair_ms.size(); ++i) {
      EXPECT_GT(r.chain_pair_ms[i], 0);
      if (!std::isfinite(sf.set_ms_per_run[i])) continue;
      ++timed;
      EXPECT_GT(sf.set_ms_per_run[i], 0);
      ratios.push_back(r.chain_pair_ms[i] / sf.set_ms_per_run[i]);
    }
    EXPECT_GE(timed, r.chain_pair_ms.size() / 2 - 1);
    EXPECT_LE(timed, r.chain_pair_ms.size() / 2 + 1);
    ASSERT_FALSE(ratios.empty());
    std::sort(ratios.begin(), ratios.end());
    const std::size_t h = ratios.size() / 2;
    const double med = ratios.size() % 2 ? ratios[h] : 0.5 * (ratios[h - 1] + ratios[h]);
    EXPECT_NEAR(r.chain_over_standalone, med, 1e-12) << (rows ? "rows" : "segments");
  }
  // The multi-threaded CPU backend: timed where the machine has several threads, and its
  // output checked bit for bit against the one-thread reference in every repetition.
  if (r.cpu_backend_threads > 1) {
    EXPECT_TRUE(std::isfinite(r.dense_cpu_mt_wall_ms));
    EXPECT_TRUE(r.cpu_backend_same_bits);
  }

  ASSERT_EQ(r.isos.size(), 1u);
  const bench::IsoResult& ir = r.isos[0];
  if (ctx) {
    // Every GPU strategy timed beside the default (lists): the dense one and the per-brick kernel.
    EXPECT_TRUE(ir.gpu.available) << ir.gpu.why;
    EXPECT_TRUE(ir.gpu_dense.available && std::isfinite(ir.gpu_dense.total_ms)) << ir.gpu_dense.why;
    EXPECT_TRUE(ir.gpu_per_brick.available && std::isfinite(ir.gpu_per_brick.total_ms)) << ir.gpu_per_brick.why;
  }
  ASSERT_EQ(ir.formats.size(), 3u);
  const bench::SparseCell* s = ir.gpu.available ? &ir.gpu : ir.cpu.available ? &ir.cpu : nullptr;
  if (!s) {
    // The sparse engines are not there yet: every sparse cell says why, no figure is made up.
    EXPECT_FALSE(ir.gpu.why.empty());
    EXPECT_FALSE(ir.cpu.why.empty());
    EXPECT_TRUE(std::isnan(ir.sparse_gpu_over_dense_cpu));
    EXPECT_TRUE(std::isnan(ir.active_percent));
    for (const auto& f : ir.formats) {
      EXPECT_FALSE(f.available);
      EXPECT_FALSE(f.why.empty());
    }
    FAIL() << "sparse engines not available: GPU '" << ir.gpu.why << "', CPU '" << ir.cpu.why << "'";
  }
  // Bricks: total from ceil(dims / 8); active from the dense CPU reference's brick min/max
  // (halo 1) of the Gaussian-smoothed field: the bricks whose range straddles tau.
  EXPECT_EQ(s->stats.bricks_total, nb);
  const engine::ChainOutput dense = engine::run_chain_cpu(v, bench::dense_list(false));
  ASSERT_TRUE(dense.bricks);
  std::size_t straddle = 0;
  const float bg = float(iso.outside_value(v.min_value, v.max_value));
  for (std::size_t i = 0; i < dense.bricks->count(); ++i) {
    float tile = 0;
    straddle += !core::tile_value(dense.bricks->min[i], dense.bricks->max[i], iso, bg, tile);
  }
  EXPECT_EQ(s->stats.active, straddle);
  EXPECT_LE(s->stats.active, s->stats.candidates);
  EXPECT_LE(s->stats.candidates, s->stats.bricks_total);
  EXPECT_NEAR(ir.active_percent, 100.0 * double(straddle) / double(nb), 1e-9);
  EXPECT_NEAR(ir.sparse_gpu_over_dense_cpu, ir.gpu.total_ms / r.dense_cpu_wall_ms, 1e-12);
  for (const auto& f : ir.formats) {
    if (!f.available) continue;
    EXPECT_EQ(f.dense_fp32_bytes, nv * 16);
    // the active bricks' samples at least, at most that plus 64 B of table/tile per brick
    const std::uint64_t pool = std::uint64_t(straddle) * core::kBrickSamples * sample_bytes(f.format);
    EXPECT_GE(f.snapshot_bytes, pool);
    EXPECT_LE(f.snapshot_bytes, pool + 64 * nb + 4096);
    EXPECT_NEAR(f.percent, 100.0 * double(f.snapshot_bytes) / double(nv * 16), 1e-9);
  }
}

TEST(BenchEngineStandalone, EveryPassGivesTheCpuChainsBitsOnOddSizes) {
  // Partial bricks in every axis, a last brick of one quad (nx % 8 == 4), ramps that put each
  // brick's extremes in its halo, and ties (+0 and -0 after rounding). Truth: the CPU chain.
  std::string why;
  engine::VulkanContext* ctx = vk(why);
  ASSERT_NE(ctx, nullptr) << "no Vulkan device: " << why;
  std::vector<engine::Volume> volumes;
  volumes.push_back(engine::make_random({44, 37, 29}, {0.8e-3, 1.1e-3, 2.0e-3}, -3.0f, 3.0f, 5));
  for (int axis = 0; axis < 3; ++axis) {
    engine::Volume v = engine::make_random({28, 21, 19}, {1e-3, 1e-3, 1e-3}, 0.0f, 0.5f, 20u + std::uint32_t(axis));
    for (int z = 0; z < 19; ++z)
      for (int y = 0; y < 21; ++y)
        for (int x = 0; x < 28; ++x) {
          const int c[3] = {x, y, z};
          float& f = v.voxels[v.grid.index(x, y, z)];
          f = std::round(f + float(axis == 1 ? -c[axis] : c[axis]));
        }
    v.update_stats();
    volumes.push_back(std::move(v));
  }
  for (const engine::Volume& v : volumes) {
    bench::StandaloneSet set(*ctx, v, 1.0);
    set.run();
    set.check(engine::run_chain_cpu(v, bench::dense_list(false)));
    const bench::StandaloneFigures f = set.figures();
    EXPECT_TRUE(f.why.empty()) << f.why;
    for (const auto& row : f.rows) EXPECT_TRUE(row.same_bits) << row.label << " on " << v.grid.dims[0];
  }
  // A volume whose rows are not whole quads is refused with the reason, not run.
  const engine::Volume odd = engine::make_random({37, 9, 9}, {1e-3, 1e-3, 1e-3}, -1.0f, 1.0f, 3);
  try {
    bench::StandaloneSet set(*ctx, odd, 1.0);
    FAIL() << "a 37-voxel row ran";
  } catch (const engine::VolumeError& e) {
    EXPECT_NE(std::string(e.what()).find("whole quads"), std::string::npos) << e.what();
  }
}

TEST(BenchEngineCase, DerivedColumnsFollowTheMeasuredOnes) {
  // A hand-made row: finish_case must recompute every derived column from these.
  bench::CaseResult r;
  r.memcpy_gbps = 4.0;
  bench::PassRow p;
  p.min_bytes = 8'000'000;
  p.gpu_ms = 2.0;
  p.cpu_ms = 8.0;
  r.passes = {p, p};
  r.dense_gpu_wall_ms = 5.0;
  r.dense_cpu_wall_ms = 20.0;
  bench::IsoResult ir;
  ir.gpu.available = true;
  ir.gpu.total_ms = 4.0;
  ir.gpu.stats.bricks_total = 200;
  ir.gpu.stats.active = 30;
  ir.gpu.stats.candidates = 50;
  bench::FormatBytes fb;
  fb.available = true;
  fb.snapshot_bytes = 15;
  fb.dense_fp32_bytes = 100;
  ir.formats = {fb};
  r.isos = {ir};
  bench::finish_case(r);
  EXPECT_DOUBLE_EQ(r.passes[0].gpu_gbps, 4.0);  // 8e6 B in 2 ms
  EXPECT_DOUBLE_EQ(r.passes[0].cpu_gbps, 1.0);
  EXPECT_DOUBLE_EQ(r.passes[0].gpu_of_memcpy, 1.0);
  EXPECT_DOUBLE_EQ(r.passes[0].cpu_of_memcpy, 0.25);
  EXPECT_DOUBLE_EQ(r.passes[0].gpu_over_cpu, 0.25);
  EXPECT_EQ(r.sum.min_bytes, 16'000'000u);
  EXPECT_DOUBLE_EQ(r.sum.gpu_ms, 4.0);
  EXPECT_DOUBLE_EQ(r.sum.cpu_ms, 16.0);
  EXPECT_DOUBLE_EQ(r.dense_gpu_over_cpu_wall, 0.25);
  EXPECT_DOUBLE_EQ(r.isos[0].sparse_gpu_over_dense_cpu, 0.2);
  EXPECT_DOUBLE_EQ(r.isos[0].sparse_gpu_over_dense_gpu, 0.8);
  EXPECT_DOUBLE_EQ(r.isos[0].active_percent, 15.0);
  EXPECT_DOUBLE_EQ(r.isos[0].candidate_percent, 25.0);
  EXPECT_DOUBLE_EQ(r.isos[0].formats[0].percent, 15.0);
  EXPECT_TRUE(std::isnan(r.isos[0].sparse_cpu_over_dense_cpu));  // no CPU figure
  EXPECT_TRUE(std::isnan(r.chain_over_standalone));  // no standalone set: no ratio
  r.standalone.why.clear();
  r.standalone.best_set_ms = 8.0;
  r.standalone.set_ms_per_run = {8.0, 2.0, 4.0};  // pairs: 1 / 8, 3 / 2, 2 / 4: the median 0.5
  r.chain_pair_ms = {1.0, 3.0, 2.0};
  bench::finish_case(r);
  EXPECT_DOUBLE_EQ(r.chain_over_standalone, 0.5);
  r.standalone.set_ms_per_run = {8.0, kNaN, 2.0, 4.0};  // a run without the best form's time: skipped
  r.chain_pair_ms = {1.0, 9.0, 3.0, 2.0};
  bench::finish_case(r);
  EXPECT_DOUBLE_EQ(r.chain_over_standalone, 0.5);
  r.chain_pair_ms.pop_back();  // pairs that do not match: no ratio
  bench::finish_case(r);
  EXPECT_TRUE(std::isnan(r.chain_over_standalone));
  r.standalone.set_ms_per_run = {8.0, 2.0, 4.0};
  r.chain_pair_ms = {1.0, 3.0, 2.0};
  r.chain_floor_ms = 2.0;
  r.chain_passes_floor_ms = 3.2;
  bench::finish_case(r);
  EXPECT_DOUBLE_EQ(r.chain_over_floor, 2.0);
  EXPECT_DOUBLE_EQ(r.chain_over_passes_floor, 1.25);
  r.standalone.why = "not run";
  // A pass without a GPU time makes the GPU sum unknown, not smaller.
  r.passes[1].gpu_ms = kNaN;
  bench::finish_case(r);
  EXPECT_TRUE(std::isnan(r.sum.gpu_ms));
  EXPECT_DOUBLE_EQ(r.sum.cpu_ms, 16.0);
}

TEST(BenchEngineCase, PeerChainsLegacyAndMemcpyColumns) {
  // Two passes of 8e6 B each (16e6 B) in 2 ms each on the GPU, 5 ms each with the legacy
  // shaders; memcpy 4 GB/s moves 16e6 B in 4 ms. Peers: 1 thread ITK 30 + 40 + 5 = 75 ms,
  // ITK + OpenVDB 30 + 6 + 20 = 56 ms; 2 threads ITK 20 + 25 + 5 = 50 ms, ITK + OpenVDB
  // 20 + 6 + 30 = 56 ms: the fastest chain is ITK at 2 threads, 50 ms.
  bench::CaseResult r;
  r.memcpy_gbps = 4.0;
  bench::PassRow p;
  p.min_bytes = 8'000'000;
  p.gpu_ms = 2.0;
  p.cpu_ms = 8.0;
  p.legacy_gpu_ms = 5.0;
  r.passes = {p, p};
  bench::PeerRow one, two;
  one.threads = 1;
  one.itk_gaussian_ms = 30;
  one.itk_gradient_ms = 40;
  one.itk_pack_ms = 5;
  one.vdb_from_dense_ms = 6;
  one.vdb_gradient_ms = 20;
  two = one;
  two.threads = 2;
  two.itk_gaussian_ms = 20;
  two.itk_gradient_ms = 25;
  two.vdb_gradient_ms = 30;
  r.peers = {one, two};
  // The copy floor: 1 ms for the gradient's bytes, 20 B per voxel: 1e6 voxels = 20e6 B,
  // 5 ms of memcpy at 4 GB/s; the pass labelled "gradient" takes 2 ms, twice the floor.
  r.passes[1].label = "gradient";
  r.voxels = 1'000'000;
  r.copy_floor_ms = 1.0;
  // The chain's floor: 8 ms against the 4 ms memcpy of the chain's 16e6 B; the passes'
  // GPU times sum to 4 ms, half the floor.
  r.chain_floor_ms = 8.0;
  bench::finish_case(r);
  EXPECT_DOUBLE_EQ(r.memcpy_ms, 4.0);
  EXPECT_DOUBLE_EQ(r.chain_floor_over_memcpy, 2.0);
  EXPECT_DOUBLE_EQ(r.chain_over_floor, 0.5);
  EXPECT_DOUBLE_EQ(r.copy_floor_memcpy_ms, 5.0);
  EXPECT_DOUBLE_EQ(r.floor_over_memcpy, 0.2);
  EXPECT_DOUBLE_EQ(r.gradient_over_floor, 2.0);
  EXPECT_DOUBLE_EQ(r.passes[0].legacy_over_gpu, 2.5);
  EXPECT_DOUBLE_EQ(r.sum.legacy_gpu_ms, 10.0);
  EXPECT_DOUBLE_EQ(r.sum.legacy_over_gpu, 2.5);
  EXPECT_DOUBLE_EQ(r.peers[0].itk_chain_ms, 75.0);
  EXPECT_DOUBLE_EQ(r.peers[0].itk_vdb_chain_ms, 56.0);
  EXPECT_DOUBLE_EQ(r.peers[1].itk_chain_ms, 50.0);
  EXPECT_DOUBLE_EQ(r.peers[1].itk_vdb_chain_ms, 56.0);
  EXPECT_DOUBLE_EQ(r.fastest_peer_chain_ms, 50.0);
  EXPECT_NE(r.fastest_peer_chain.find("2 threads"), std::string::npos) << r.fastest_peer_chain;
  EXPECT_NE(r.fastest_peer_chain.find("ITK gradient"), std::string::npos) << r.fastest_peer_chain;
  EXPECT_DOUBLE_EQ(r.chain_over_peer, 4.0 / 50.0);
  EXPECT_DOUBLE_EQ(r.memcpy_ms, 4.0);
  EXPECT_DOUBLE_EQ(r.chain_over_memcpy, 1.0);
  // A peer that did not run (NaN) is not the fastest.
  r.peers[1].itk_gradient_ms = kNaN;
  bench::finish_case(r);
  EXPECT_DOUBLE_EQ(r.fastest_peer_chain_ms, 56.0);
}

// The end-to-end child on a small sphere: the split from the volume to the first servo tick
// is reported (the chain's stages within its wall time, the hand-over, the first tick), and
// the ticks after it touch the surface (HRI renders a force: the HIP path meets the sphere).
TEST(BenchEngineBig, ChildReportsTheSplitToTheFirstTick) {
  std::ostringstream out, progress;
  ASSERT_EQ(bench::run_big_child(32, "", out, progress), 0) << out.str() << progress.str();
  auto kv = bench::parse_key_values(out.str());
  for (const char* k : {"make_ms", "setup_ms", "step_ms", "stages", "publish_ms", "first_tick_us", "ticks_median_us",
                        "max_force_n"})
    ASSERT_TRUE(kv.count(k)) << k << " missing in\n" << out.str();
  const int stages = std::stoi(kv["stages"]);
  ASSERT_GE(stages, 3) << out.str();
  double staged = 0;
  for (int i = 0; i < stages; ++i) {
    const std::string k = "stage" + std::to_string(i);
    ASSERT_TRUE(kv.count(k + "_ms") && kv.count(k + "_label")) << k;
    EXPECT_GE(std::stod(kv[k + "_ms"]), 0.0) << k;
    staged += std::stod(kv[k + "_ms"]);
  }
  EXPECT_LE(staged, std::stod(kv["step_ms"]) * 1.001 + 0.01) << "stages beyond the run's wall time";
  EXPECT_GT(std::stod(kv["first_tick_us"]), 0.0);
  EXPECT_GT(std::stod(kv["max_force_n"]), 0.05) << "the ticks never touched the sphere";
}
