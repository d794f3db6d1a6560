// End to end on a synthetic sphere of radius 20 voxels: GPU samples -> HRI -> device.
// During the sliding contact the VHIP stays within 0.05 voxel of the analytic sphere and
// the force direction within 2 degrees of the analytic normal.
#include <gtest/gtest.h>

#include <cmath>

#include "isotouch/engine/gradient_pass.h"
#include "isotouch/sim/headless.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/engine/vk_context.h"

using namespace isotouch;
using core::Vec3;

namespace {
struct Errors {
  double max_surface_vox = 0, max_angle_deg = 0;
  long sliding_ticks = 0;
};

Errors slide(int n, Vec3 ray_dir, Vec3 origin_frac, Vec3 stroke_dir) {
  const double h = 1e-3, R_vox = 20.0;
  const engine::Volume vol = engine::make_sphere({64, 64, 64}, h, R_vox);
  auto ctx = engine::VulkanContext::create();
  if (!ctx) throw std::runtime_error("no Vulkan device: " + ctx.error);
  engine::GradientPass pass(**ctx.value);
  auto field = std::make_shared<const core::SampleField>(pass.run(vol));
  servo::TripleBuffer<core::SampleField> tb;
  tb.publish(field);

  servo::HriParams hp;
  hp.tau = 0;
  hp.plane_update_period = n;
  hp.stiffness_n_per_m = 800;
  hp.damping_n_s_per_m = 1.0;
  sim::ScriptParams sp;
  sp.ray_origin_frac = origin_frac;
  sp.ray_direction = ray_dir;
  sp.stroke_direction = stroke_dir;
  sp.press_depth_m = 0.004;
  sp.stroke_length_m = 0.025;
  sp.stroke_speed_m_s = 0.02;
  const sim::TouchScript s = sim::make_touch_script(*field, hp, sp);
  servo::WorkspaceTransform xf;
  xf.translation_m = vol.grid.centre_m();
  Vec3 p0, v0;
  s.at(0, p0, v0);
  sim::SimDevice dev({}, xf.to_device(p0));
  servo::HriRenderer r(hp);
  const auto trace = sim::run_headless(tb, r, dev, xf, s, 1000.0);

  const Vec3 c = vol.grid.centre_m();
  const double R = R_vox * h;
  Errors e;
  for (const auto& row : trace) {
    if (!row.contact || row.t_s < s.t_stroke || row.t_s > s.t_lift) continue;
    ++e.sliding_ticks;
    e.max_surface_vox = std::max(e.max_surface_vox, std::abs(core::norm(row.vhip_m - c) - R) / h);
    const double f = core::norm(row.force_n);
    if (f < 0.05) continue;  // direction of a vanishing force is meaningless
    const Vec3 n_true = (row.vhip_m - c) / core::norm(row.vhip_m - c);
    const double cosang = std::clamp(core::dot(row.force_n / f, n_true), -1.0, 1.0);
    e.max_angle_deg = std::max(e.max_angle_deg, std::acos(cosang) * 180.0 / M_PI);
  }
  return e;
}
}  // namespace

TEST(SphereIntegration, SlidingOverTheTopWithPlaneEveryTick) {
  const Errors e = slide(1, {0, 0, -1}, {0.5, 0.5, 1.2}, {1, 0, 0});
  std::printf("n=1 top: %ld sliding ticks, max surface error %.4f voxel, max angle %.3f deg\n",
              e.sliding_ticks, e.max_surface_vox, e.max_angle_deg);
  EXPECT_GT(e.sliding_ticks, 500);
  EXPECT_LT(e.max_surface_vox, 0.05);
  EXPECT_LT(e.max_angle_deg, 2.0);
}

TEST(SphereIntegration, SlidingObliquelyAcrossVoxelAxes) {
  const Vec3 d = Vec3{-1, -0.7, -0.4} / core::norm(Vec3{-1, -0.7, -0.4});
  const Errors e = slide(1, d, {1.1, 0.95, 0.8}, {0.3, -1, 0.5});
  std::printf("n=1 oblique: %ld sliding ticks, max surface error %.4f voxel, max angle %.3f deg\n",
              e.sliding_ticks, e.max_surface_vox, e.max_angle_deg);
  EXPECT_GT(e.sliding_ticks, 500);
  EXPECT_LT(e.max_surface_vox, 0.05);
  EXPECT_LT(e.max_angle_deg, 2.0);
}
