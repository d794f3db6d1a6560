// Gradient pass: CPU reference against analytic truth, GPU against the CPU reference.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>

#include "isotouch/tests/vk_test_context.h"
#include "isotouch/tests/gpu_cpu_compare.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/gradient_pass.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/engine/vk_context.h"

using namespace isotouch;
using engine::Volume;
using core::Vec3;

namespace {
const std::string kData = ISOTOUCH_TEST_DATA;

// The validated context (tests/vk_test_context.h): every dispatch below must leave it silent.
engine::VulkanContext& vk() { return test::validated_vk(); }

// Bit for bit, channel by channel; two NaNs count as equal whatever their payload.
bool same_bits(float a, float b) {
  return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b) || (std::isnan(a) && std::isnan(b));
}

void expect_gpu_equals_cpu(const Volume& v, std::uint64_t max_binding = 0, int min_slabs = 1) {
  engine::GradientPass pass(vk());
  engine::GradientTimings t;
  const auto gpu = pass.run(v, &t, max_binding);
  const auto cpu = engine::compute_samples_cpu(v);
  const auto d = engine::compare_gradients(gpu, cpu);
  EXPECT_GE(t.slabs, min_slabs);
  EXPECT_EQ(d.nonfinite, 0u);
  EXPECT_GT(d.max_gradient_norm, 0.0);
  EXPECT_EQ(d.max_value_abs, 0.0) << "the value channel is copied, not computed";
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
  ASSERT_EQ(gpu.samples.size(), cpu.samples.size());
  if (isotouch::test::expects_bit_identity(vk())) {
    // The README's claim: on lavapipe GPU and CPU agree bit for bit (same float operations
    // in the same order). Exact equality of every channel of every sample.
    std::size_t differ = 0, first = 0;
    for (std::size_t i = 0; i < cpu.samples.size(); ++i) {
      const core::Sample &a = gpu.samples[i], &b = cpu.samples[i];
      if (!(same_bits(a.value, b.value) && same_bits(a.gx, b.gx) && same_bits(a.gy, b.gy) && same_bits(a.gz, b.gz)))
        first = differ++ ? first : i;
    }
    EXPECT_EQ(differ, 0u) << v.path << ": " << differ << " samples differ in their bits, first at index " << first
                          << " (GPU " << gpu.samples[first].gx << " " << gpu.samples[first].gy << " "
                          << gpu.samples[first].gz << ", CPU " << cpu.samples[first].gx << " " << cpu.samples[first].gy
                          << " " << cpu.samples[first].gz << ")";
  } else {
    // Another driver may contract to FMA or reorder: 1e-6 of the largest gradient.
    EXPECT_LE(d.max_rel, 1e-6) << v.path << ": max abs " << d.max_abs_all << " of " << d.max_gradient_norm;
  }
}
}  // namespace

TEST(CpuGradient, LinearFieldIsExactIncludingBorders) {
  const Vec3 a{120.0, -40.0, 75.0};  // value per metre
  const Volume v = engine::make_linear({9, 7, 5}, {2e-3, 1e-3, 3e-3}, a, 10.0);
  const auto f = engine::compute_samples_cpu(v);
  for (const auto& s : f.samples) {
    EXPECT_NEAR(s.gx, a.x, 1e-3 * std::abs(a.x));
    EXPECT_NEAR(s.gy, a.y, 1e-3 * std::abs(a.y));
    EXPECT_NEAR(s.gz, a.z, 1e-3 * std::abs(a.z));
  }
}

TEST(CpuGradient, SphereDistanceHasUnitSlopeAndRadialDirection) {
  const Volume v = engine::make_sphere({48, 48, 48}, 1e-3, 15.0);
  const auto f = engine::compute_samples_cpu(v);
  const Vec3 c = v.grid.centre_m();
  int checked = 0;
  for (int z = 1; z < 47; ++z)
    for (int y = 1; y < 47; ++y)
      for (int x = 1; x < 47; ++x) {
        const Vec3 p = v.grid.to_world({double(x), double(y), double(z)});
        const double r = core::norm(p - c) * 1e3;
        if (std::abs(r - 15.0) > 1.5) continue;  // near the surface
        const auto& s = f.samples[v.grid.index(x, y, z)];
        const Vec3 g{s.gx, s.gy, s.gz};
        EXPECT_NEAR(core::norm(g), 1000.0, 20.0);  // value in mm, gradient per m
        const double cosang = core::dot(g / core::norm(g), (c - p) / core::norm(c - p));
        EXPECT_GT(cosang, std::cos(2.0 * M_PI / 180.0));
        ++checked;
      }
  EXPECT_GT(checked, 1000);
}

TEST(CpuGradient, OneVoxelAxisHasZeroDerivative) {
  const Volume v = engine::make_linear({4, 4, 1}, {1e-3, 1e-3, 1e-3}, {1, 2, 3}, 0);
  for (const auto& s : engine::compute_samples_cpu(v).samples) EXPECT_EQ(s.gz, 0.f);
}

TEST(GpuGradient, DeviceHasAName) {
  EXPECT_FALSE(vk().info().name.empty());
  std::printf("Vulkan device: %s (%s)\n", vk().info().name.c_str(), vk().info().type.c_str());
}

TEST(GpuGradient, MatchesCpuOnSphere) {
  expect_gpu_equals_cpu(engine::make_sphere({64, 64, 64}, 1e-3, 20.0));
}

TEST(GpuGradient, MatchesCpuOnRandomOddSizedVolumeInManySlabs) {
  const Volume v = engine::make_random({37, 23, 41}, {1.1e-3, 0.7e-3, 2.3e-3}, -1000.f, 3000.f, 7);
  // Bindings limited to ~3 z-slices of samples: forces slabs and unaligned offsets.
  expect_gpu_equals_cpu(v, 37 * 23 * 16 * 3 + 256, 10);
}

TEST(GpuGradient, MatchesCpuOnHeadCt) {
  expect_gpu_equals_cpu(io::load_volume(kData + "/ct-head-headsq/headsq_64x64x93_int16.mhd"));
}

TEST(GpuGradient, MatchesCpuOnChestCt) {
  expect_gpu_equals_cpu(
      io::load_volume(kData + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd"));
}

TEST(GpuGradient, MatchesCpuOnToothBigEndian) {
  expect_gpu_equals_cpu(io::load_volume(kData + "/ct-tooth/tooth.nhdr"), 4u << 20, 2);
}

TEST(GpuGradient, EngineCtNeedsSlabsUnderTheDeviceLimit) {
  // 256 x 256 x 128 samples = 128 MiB: more than lavapipe's 128 MiB binding minus alignment.
  expect_gpu_equals_cpu(io::load_volume(kData + "/ct-engine/engine.nii.gz"), 0,
                        vk().properties().limits.maxStorageBufferRange <= (128u << 20) ? 2 : 1);
}

TEST(GpuGradient, SliceLargerThanBindingIsAClearError) {
  const Volume v = engine::make_random({64, 64, 4}, {1e-3, 1e-3, 1e-3}, 0.f, 1.f, 1);
  engine::GradientPass pass(vk());
  try {
    pass.run(v, nullptr, 1024);
    FAIL() << "no error";
  } catch (const engine::VolumeError& e) {
    EXPECT_NE(std::string(e.what()).find("does not fit"), std::string::npos) << e.what();
  }
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

TEST(GpuGradient, CopyFloorIsAFinitePositiveDeviceTime) {
  // copy_x4 (the gradient's loads and stores without arithmetic) runs on a volume in several
  // slabs' worth of dispatches and returns a finite positive time.
  const engine::Volume v = engine::make_random({67, 45, 33}, {1e-3, 1e-3, 1e-3}, -1.0f, 1.0f, 9);
  engine::GradientPass pass(vk());
  using T = engine::GradientPass::FloorTraffic;
  for (T t : {T::Samples, T::Floats, T::ReadOnly}) {  // the gradient's, a filter's, brick min/max's traffic
    const double floor_ms = pass.copy_floor_ms(v, 3, t);
    EXPECT_TRUE(std::isfinite(floor_ms)) << int(t);
    EXPECT_GT(floor_ms, 0.0) << int(t);
  }
  // Rows of whole quads (one 16 B store per quad for a filter's traffic) and not.
  const engine::Volume q = engine::make_random({68, 45, 33}, {1e-3, 1e-3, 1e-3}, -1.0f, 1.0f, 9);
  EXPECT_GT(pass.copy_floor_ms(q, 3, T::Floats), 0.0);
  EXPECT_EQ(vk().validation_messages(), 0u);
}
