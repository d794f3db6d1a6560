// Sweeps: recorded strokes, playback and error figures against the truth.
#include <gtest/gtest.h>

#include <sstream>

#include "isotouch/servo/baselines.h"
#include "isotouch/servo/hri.h"
#include "isotouch/eval/sweep.h"

using namespace isotouch;

TEST(Sweep, SphereHriN1RefinedStaysWithinTwoHundredthsOfAVoxel) {
  std::ostringstream log;
  const eval::SweepScene s = eval::prepare_sweep_scene("sphere", nullptr, log);
  ASSERT_GT(s.hip.size(), 1000u);
  for (servo::Intersection m : {servo::Intersection::kSecant, servo::Intersection::kBisection}) {
    servo::HriParams p = eval::reference_params(s);
    p.plane_update_period = 1;
    p.intersection = m;
    p.intersection_steps = m == servo::Intersection::kSecant ? 4 : 8;
    p.normal = servo::NormalSource::kSamples;
    servo::HriRenderer r(p);
    const eval::ErrorFigures e = eval::measure(s, eval::playback(r, s));
    EXPECT_GT(e.contact_ticks, 500);
    EXPECT_LE(e.surface_err_rms_m / s.voxel_m, 0.02);
    EXPECT_LT(e.angle_err_rms_deg, 1.0);
  }
}

TEST(Sweep, ErrorsGrowWithThePlaneUpdatePeriodOnTheSphere) {
  std::ostringstream log;
  const eval::SweepScene s = eval::prepare_sweep_scene("sphere", nullptr, log);
  double prev = -1;
  for (int n : {1, 10, 50}) {
    servo::HriParams p = eval::reference_params(s);
    p.plane_update_period = n;
    p.intersection = servo::Intersection::kLinear;
    p.normal = servo::NormalSource::kSamples;
    servo::HriRenderer r(p);
    const eval::ErrorFigures e = eval::measure(s, eval::playback(r, s));
    EXPECT_GT(e.angle_err_rms_deg, prev) << "n = " << n;  // stale planes tilt the force
    prev = e.angle_err_rms_deg;
  }
}

TEST(Sweep, BaselinesReplayAndAreMeasured) {
  std::ostringstream log;
  const eval::SweepScene s = eval::prepare_sweep_scene("knot", nullptr, log);
  servo::BaselineParams b;
  b.tau = s.tau;
  b.stiffness_n_per_m = s.stiffness_n_per_m;
  b.damping_n_s_per_m = 0;
  b.force_limit_n = 1e3;
  servo::AvilaRenderer a(b);
  servo::BlezekRenderer z(b);
  for (servo::Renderer* r : std::initializer_list<servo::Renderer*>{&a, &z}) {
    const eval::ErrorFigures e = eval::measure(s, eval::playback(*r, s));
    EXPECT_GT(e.contact_ticks, 200) << r->name();
    EXPECT_LT(e.surface_err_rms_m / s.voxel_m, 0.1) << r->name();
    EXPECT_LT(e.angle_err_rms_deg, 5.0) << r->name();
    EXPECT_GT(eval::median_ns_per_tick(*r, s, 0, 3), 0.0);
  }
}

namespace {
// Replays the reference renderer but drops the contact (zero force) on every 100th tick.
class DropEvery100 final : public servo::Renderer {
 public:
  explicit DropEvery100(const servo::HriParams& p) : r_(p) {}
  const char* name() const override { return "drop"; }
  void reset() override {
    r_.reset();
    k_ = 0;
  }
  using servo::Renderer::tick;
  servo::HriTick tick(const core::SampleField& f, const core::Vec3& hip, double dt) override {
    servo::HriTick t = r_.tick(f, hip, dt);
    if (++k_ % 100 == 0) {
      t.contact = false;
      t.force_n = {};
    }
    return t;
  }

 private:
  servo::HriRenderer r_;
  long k_ = 0;
};
}  // namespace

// A pop-through is a contact lost while the HIP is more than half a voxel inside: none for
// the reference renderer on the sphere; one per dropped tick that is that deep.
TEST(Sweep, PopThroughsAreCountedAgainstTheTruth) {
  std::ostringstream log;
  const eval::SweepScene s = eval::prepare_sweep_scene("sphere", nullptr, log);
  servo::HriRenderer ref(eval::reference_params(s));
  EXPECT_EQ(eval::measure(s, eval::playback(ref, s)).pop_throughs, 0);
  DropEvery100 drop(eval::reference_params(s));
  long expected = 0;
  const eval::Playback p = eval::playback(drop, s);
  for (std::size_t k = 1; k < s.hip.size(); ++k)
    expected += (k + 1) % 100 == 0 && p.ticks[k - 1].contact && s.truth->depth(s.hip[k]) > 0.5 * s.voxel_m;
  EXPECT_GT(expected, 0);
  EXPECT_EQ(eval::measure(s, p).pop_throughs, expected);
}
