// The synthetic scenes: sampled volume against its exact shape (the truth).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/servo/sampling.h"
#include "isotouch/eval/shapes.h"

using namespace isotouch;
using core::Vec3;

TEST(Shapes, TruthIsConsistent) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.005, 0.058);
  for (const std::string& name : eval::synthetic_scene_names()) {
    const eval::SyntheticScene s = eval::make_synthetic_scene(name);
    for (int i = 0; i < 300; ++i) {
      const Vec3 x{u(rng), u(rng), u(rng)};
      Vec3 p, n;
      s.truth->closest(x, p, n);
      EXPECT_NEAR(core::norm(n), 1.0, 1e-12) << name;
      EXPECT_NEAR(s.truth->depth(p), 0.0, 1e-9) << name;  // the closest point is on the surface
      // |depth| is the distance to that point (inside and outside)
      EXPECT_NEAR(std::abs(s.truth->depth(x)), core::norm(x - p), 1e-9) << name;
    }
  }
}

TEST(Shapes, KnotDistanceMatchesBruteForce) {
  const eval::SyntheticScene s = eval::make_synthetic_scene("knot");
  const Vec3 c = s.volume.grid.centre_m();
  auto curve = [&](double t) {
    const double rho = 0.014 + 0.008 * std::cos(3 * t);
    return c + Vec3{rho * std::cos(2 * t), rho * std::sin(2 * t), 0.008 * std::sin(3 * t)};
  };
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.026, 0.026);
  for (int i = 0; i < 40; ++i) {
    const Vec3 x = c + Vec3{u(rng), u(rng), u(rng) * 0.4};
    double best = 1e300;
    for (int k = 0; k < 200000; ++k) best = std::min(best, core::norm(curve(2 * M_PI * k / 200000) - x));
    EXPECT_NEAR(s.truth->depth(x), 0.0035 - best, 2e-7);
  }
}

TEST(Shapes, SampledIsosurfaceLiesOnTheTruth) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.004, 0.059);
  for (const std::string& name : eval::synthetic_scene_names()) {
    const eval::SyntheticScene s = eval::make_synthetic_scene(name);
    const core::SampleField f = engine::compute_samples_cpu(s.volume);
    double worst = 0;
    int n_checked = 0;
    for (int i = 0; i < 2000 && n_checked < 300; ++i) {
      const Vec3 x{u(rng), u(rng), u(rng)};
      Vec3 p, n;
      s.truth->closest(x, p, n);
      // Away from box edges and sphere junctions, where trilinear rounds corners.
      if (name == "box" || name == "three-spheres") {
        Vec3 p2, n2;
        s.truth->closest(p + n * -0.0025, p2, n2);
        if (core::norm(p2 - p) > 1e-6) continue;
      }
      const double g = core::norm(servo::trilinear_field_gradient(f, p));
      if (!(g > 0)) continue;
      const double dist = std::abs(servo::sample_value(f, p) - s.tau) / g;  // first order
      worst = std::max(worst, dist);
      ++n_checked;
    }
    std::printf("%-14s sampled isosurface within %.4f voxel of the truth (%d points)\n", name.c_str(),
                worst / 1e-3, n_checked);
    EXPECT_GT(n_checked, 100) << name;
    EXPECT_LT(worst, 0.1e-3) << name;  // 0.1 voxel
  }
}

TEST(Shapes, KnotPathSlidesOnTheConcaveSide) {
  const eval::SyntheticScene s = eval::make_synthetic_scene("knot");
  ASSERT_GT(s.hip_path.size(), 500u);
  int deep = 0;
  for (const Vec3& h : s.hip_path) {
    const double d = s.truth->depth(h);
    EXPECT_LT(d, 0.0005 + 1e-9);
    deep += std::abs(d - 0.0005) < 1e-6;
  }
  EXPECT_GE(deep, 250);  // the sliding part holds 0.5 mm deep
  // Concave along the path: the chord between two sliding points dips into the object
  // less than the path itself, i.e. the midpoint of the surface points lies outside.
  Vec3 p0, n0, p1, n1;
  s.truth->closest(s.hip_path[260], p0, n0);
  s.truth->closest(s.hip_path[480], p1, n1);
  EXPECT_LT(s.truth->depth((p0 + p1) * 0.5), 0.0);
}
