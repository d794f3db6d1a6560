// test_bench_edit.cpp - the pure parts of `isotouch bench edit` (bench/bench_edit.h) against
// truths from outside them: the nearest-rank definition checked by brute force, an analytic
// sphere, edge crossings counted directly on the raw voxels, and a fake renderer.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <cmath>
#include <limits>
#include <random>
#include <thread>

#include "isotouch/bench/bench_edit.h"
#include "isotouch/bench/edit_floor.h"
#include "isotouch/core/field_view.h"
#include "isotouch/session/live_field.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/synthetic.h"

using namespace isotouch;
using eval::percentile;

namespace {
const double kNaN = std::numeric_limits<double>::quiet_NaN();

// The definition, by brute force: r is a value of x, at least q n values are <= r, and
// fewer than q n values are < r (so no smaller value of x qualifies).
void expect_nearest_rank(const std::vector<double>& x, double q) {
  const double r = percentile(x, q);
  const double n = double(x.size());
  long le = 0, lt = 0;
  bool member = false;
  for (double v : x) {
    le += v <= r;
    lt += v < r;
    member = member || v == r;
  }
  EXPECT_TRUE(member) << "q " << q;
  EXPECT_GE(double(le), q * n - 1e-9) << "q " << q;
  if (q > 0) {
    EXPECT_LT(double(lt), q * n - 1e-9) << "q " << q;
  }
}
}  // namespace

TEST(BenchEdit, PercentileIsTheNearestRank) {
  std::vector<double> x;
  for (int i = 1; i <= 100; ++i) x.push_back(double(101 - i));  // 100 .. 1, unsorted
  EXPECT_EQ(percentile(x, 0.99), 99.0);
  EXPECT_EQ(percentile(x, 0.5), 50.0);
  EXPECT_EQ(percentile(x, 1.0), 100.0);
  EXPECT_EQ(percentile(x, 0.0), 1.0);
  EXPECT_EQ(percentile({7.0}, 0.99), 7.0);
  std::mt19937 rng(3);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<double> y(1 + rng() % 300);
    for (double& v : y) v = double(rng() % 50);  // many ties
    for (double q : {0.0, 0.01, 0.25, 0.5, 0.9, 0.99, 0.999, 1.0}) expect_nearest_rank(y, q);
  }
}

TEST(BenchEdit, PercentileDropsNaNAndEmptyIsNaN) {
  EXPECT_TRUE(std::isnan(percentile({}, 0.5)));
  EXPECT_TRUE(std::isnan(percentile({kNaN, kNaN}, 0.5)));
  EXPECT_EQ(percentile({kNaN, 3.0, kNaN, 1.0, 2.0}, 1.0), 3.0);
  EXPECT_EQ(percentile({kNaN, 3.0, kNaN, 1.0, 2.0}, 0.0), 1.0);
  const bench::Spread s = bench::spread({kNaN, 4.0, 1.0, 3.0, 2.0});
  EXPECT_EQ(s.n, 4u);
  EXPECT_EQ(s.median, 2.5);  // mean of the middle two
  EXPECT_EQ(s.p99, 4.0);
  EXPECT_EQ(s.max, 4.0);
}

TEST(BenchEdit, MissesVerdictAllowsThreeSigmaAboveIdle) {
  EXPECT_TRUE(bench::misses_verdict(0, 24000, 0, 24000).met);
  EXPECT_FALSE(bench::misses_verdict(1, 24000, 0, 24000).met);  // ref 0: no allowance
  // ref 7: limit 7 + 3 sqrt(7) = 14.94.
  EXPECT_TRUE(bench::misses_verdict(14, 24000, 7, 24000).met);
  EXPECT_FALSE(bench::misses_verdict(15, 24000, 7, 24000).met);
  // The coordinator's run: 47 in 23951 against 7 in 23993 (ref 6.99, limit 14.92).
  EXPECT_FALSE(bench::misses_verdict(47, 23951, 7, 23993).met);
  // Scaled by ticks: idle 4 in 20000, editing 40000 ticks: ref 8, limit 16.49.
  EXPECT_TRUE(bench::misses_verdict(16, 40000, 4, 20000).met);
  EXPECT_FALSE(bench::misses_verdict(17, 40000, 4, 20000).met);
  const bench::Verdict v = bench::misses_verdict(5, 0, 0, 1000);
  EXPECT_FALSE(v.measured);
  EXPECT_FALSE(v.met);
  EXPECT_NE(v.text.find("not measured"), std::string::npos);
  // Too few ticks to judge: undecided, whatever the counts.
  const bench::Verdict u = bench::misses_verdict(0, 19999, 0, 24000);
  EXPECT_FALSE(u.measured);
  EXPECT_NE(u.text.find("undecided"), std::string::npos) << u.text;
  const bench::Verdict w = bench::misses_verdict(1, 24000, 0, 24000);
  EXPECT_TRUE(w.measured);
  EXPECT_NE(w.text.find("NOT met"), std::string::npos) << w.text;
}

TEST(BenchEdit, AtLeastVerdict) {
  EXPECT_TRUE(bench::verdict_at_least("rate", 200.0, 200.0).met);
  EXPECT_FALSE(bench::verdict_at_least("rate", 199.9, 200.0).met);
  const bench::Verdict v = bench::verdict_at_least("rate", kNaN, 200.0, 1, "no phase");
  EXPECT_FALSE(v.measured);
  EXPECT_NE(v.text.find("not measured (no phase)"), std::string::npos) << v.text;
}

TEST(BenchEdit, ChangedVoxelsComparesBits) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float a[] = {1.f, nan, 0.f, 2.f, -3.f};
  const float b[] = {1.f, nan, -0.f, 2.5f, -3.f};
  EXPECT_EQ(bench::changed_voxels(a, b, 5), 2u);  // 0 vs -0 and 2 vs 2.5
  EXPECT_EQ(bench::changed_voxels(a, a, 5), 0u);
}

namespace {
// Sign-change edges between interior voxel centres, counted on the raw voxels.
std::size_t brute_force_crossings(const engine::Volume& v, const core::Isosurface& iso) {
  const auto& d = v.grid.dims;
  auto in = [&](int x, int y, int z) { return iso.contains(v.voxels[v.grid.index(x, y, z)]); };
  std::size_t n = 0;
  for (int z = 1; z <= d[2] - 2; ++z)
    for (int y = 1; y <= d[1] - 2; ++y)
      for (int x = 1; x <= d[0] - 2; ++x) {
        if (x + 1 <= d[0] - 2 && in(x, y, z) != in(x + 1, y, z)) ++n;
        if (y + 1 <= d[1] - 2 && in(x, y, z) != in(x, y + 1, z)) ++n;
        if (z + 1 <= d[2] - 2 && in(x, y, z) != in(x, y, z + 1)) ++n;
      }
  return n;
}
}  // namespace

TEST(BenchEdit, SurfacePointsLieOnAnAnalyticSphere) {
  const double h = 1e-3, r_vox = 11.0;
  const std::array<double, 3> off{0.3, -0.2, 0.1};
  const engine::Volume vol = engine::make_sphere({36, 34, 32}, h, r_vox, off);
  const core::SampleField f = engine::compute_samples_cpu(vol);
  const core::Isosurface iso{0.0, core::InsideIs::kAbove};
  const core::Vec3 c = vol.grid.centre_m() + core::Vec3{off[0], off[1], off[2]} * h;

  // Every crossing, nothing avoided: as many as the raw voxels have, all on the sphere.
  const std::vector<core::Vec3> all = bench::surface_points(f, iso, 1u << 20, 7, c, 0.0);
  EXPECT_EQ(all.size(), brute_force_crossings(vol, iso));
  ASSERT_GT(all.size(), 500u);
  for (const auto& p : all) EXPECT_LT(std::abs(core::norm(p - c) - r_vox * h), 0.02 * h);

  // A count, an avoided ball around a point on the sphere, a fixed order per seed.
  const core::Vec3 probe = c + core::Vec3{r_vox * h, 0, 0};
  const double avoid = 6 * h;
  const auto a = bench::surface_points(f, iso, 100, 7, probe, avoid);
  const auto b = bench::surface_points(f, iso, 100, 7, probe, avoid);
  const auto other = bench::surface_points(f, iso, 100, 8, probe, avoid);
  ASSERT_EQ(a.size(), 100u);
  for (const auto& p : a) EXPECT_GT(core::norm(p - probe), avoid);
  bool same = true, differs = false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    same = same && a[i].x == b[i].x && a[i].y == b[i].y && a[i].z == b[i].z;
    differs = differs || a[i].x != other[i].x || a[i].y != other[i].y || a[i].z != other[i].z;
  }
  EXPECT_TRUE(same);
  EXPECT_TRUE(differs);
  // Spread over the sphere, not one cluster: both hemispheres along each axis.
  for (int axis = 0; axis < 3; ++axis) {
    int lo = 0, hi = 0;
    for (const auto& p : a) ((p - c)[axis] < 0 ? lo : hi)++;
    EXPECT_GT(lo, 10) << "axis " << axis;
    EXPECT_GT(hi, 10) << "axis " << axis;
  }
}

namespace {
// Counts its ticks; in contact on every other one.
class FakeRenderer final : public servo::Renderer {
 public:
  const char* name() const override { return "fake"; }
  void reset() override {}
  using servo::Renderer::tick;
  servo::HriTick tick(const core::FieldView&, const core::Vec3&, double) override {
    servo::HriTick t;
    t.contact = (calls++ % 2) == 0;
    return t;
  }
  long calls = 0;
};

std::int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
}  // namespace

TEST(BenchEdit, VersionSpyNotesTheFirstTickOfEachVersion) {
  FakeRenderer inner;
  bench::VersionSpy spy(inner, 8);
  core::SampleField f;  // empty: the fake never reads it
  auto tick = [&](std::uint64_t v) {
    f.version = v;
    (void)static_cast<servo::Renderer&>(spy).tick(f, core::Vec3{}, 0.0);  // as the servo thread calls it
  };
  const std::int64_t t_start = steady_ns();
  tick(1);
  tick(1);
  const std::int64_t t1 = spy.seen_ns(1);
  EXPECT_GE(t1, t_start);
  EXPECT_EQ(spy.seen_ns(2), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(2));
  const std::int64_t t_before2 = steady_ns();
  tick(2);
  EXPECT_GE(spy.seen_ns(2), t_before2);
  EXPECT_LE(spy.seen_ns(2), steady_ns());
  tick(1);  // an older version seen again keeps its first time
  EXPECT_EQ(spy.seen_ns(1), t1);
  tick(5);
  tick(9);  // past the capacity: not noted, no crash
  EXPECT_GT(spy.seen_ns(5), 0);
  EXPECT_EQ(spy.seen_ns(3), 0);
  EXPECT_EQ(spy.seen_ns(9), 0);
  EXPECT_EQ(spy.seen_ns(1000), 0);
  EXPECT_EQ(inner.calls, 6);  // six ticks, every one passed on
  EXPECT_EQ(spy.ticks(), 6);
  EXPECT_EQ(spy.contact_ticks(), 3);  // the fake: ticks 1, 3, 5
}

// The floor program builds the same snapshots as the product's live field for the same
// brushes (every voxel's sample read through FieldView, bit for bit), with a gradient alone
// and with a Gaussian (a wider reach), carve and add, inside and at the border: it does the
// same work. Truth: session::LiveField, itself checked against run_sparse_cpu
// (tests/test_live_field.cpp).
TEST(BenchEdit, FloorProgramPublishesTheLiveFieldsSnapshots) {
  engine::Volume v = engine::make_sphere({37, 29, 21}, 1e-3, 9.0);
  v.update_stats();
  const core::Isosurface iso{0.0, core::InsideIs::kBelow};
  const auto targets = session::default_targets(v, iso);
  for (const auto& passes : {std::vector<engine::PassDesc>{engine::PassDesc::gradient()},
                             std::vector<engine::PassDesc>{engine::PassDesc::gaussian(1.0), engine::PassDesc::gradient()}}) {
    session::LiveFieldOptions o;
    o.passes = passes;
    o.iso = iso;
    o.background = float(iso.outside_value(v.min_value, v.max_value));
    auto live = session::LiveField::create(v, o);
    engine::Volume product = v;
    bench::EditFloor floor(v, *live->current(), passes, iso, 256);
    const core::Grid& g = v.grid;
    // Centres whose brush box starts or ends at a brick's first or last voxels (the reach
    // across brick borders: 11.5 - 3 voxels starts at voxel 8), and at the grid's border.
    const core::Vec3 at[] = {g.to_world({18.0, 14.0, 10.0}), g.to_world({11.5, 11.5, 11.5}), g.to_world({0.5, 1.0, 0.0}),
                             g.to_world({19.5, 12.2, 4.6}),  g.to_world({4.5, 20.5, 12.5}), g.to_world({27.5, 4.5, 19.5})};
    std::uint64_t version = 2;
    for (int k = 0; k < 24; ++k) {
      session::Brush b;
      b.kind = k % 2 ? session::BrushKind::kAdd : session::BrushKind::kCarve;
      b.centre_m = at[(k / 2) % 6];
      b.radius_m = 3e-3;
      b.strength = 0.6 * std::abs(double(targets.material) - double(targets.empty));
      b.targets = targets;
      const session::BrushResult r = session::apply_brush_cpu(product, b);
      const bench::FloorStep f = floor.apply(b, version);
      ASSERT_EQ(f.dirty, r.dirty.size()) << "edit " << k;
      if (r.dirty.empty()) continue;
      const auto snap = live->update(product, r.dirty);
      ASSERT_TRUE(f.snapshot) << "edit " << k;
      EXPECT_EQ(f.snapshot->version, version++);
      const core::FieldView a(*snap), c(*f.snapshot);
      std::size_t differ = 0;
      for (int z = 0; z < g.dims[2]; ++z)
        for (int y = 0; y < g.dims[1]; ++y)
          for (int x = 0; x < g.dims[0]; ++x) {
            const core::Sample sa = a.voxel(x, y, z), sc = c.voxel(x, y, z);
            differ += std::memcmp(&sa, &sc, sizeof sa) != 0;
          }
      EXPECT_EQ(differ, 0u) << "edit " << k << " (" << passes.size() << " passes): voxels whose samples differ";
    }
  }
}
