// gpu_cpu_compare.h - the one rule by which the tests compare a GPU result with its CPU
// reference, whatever the device:
// - a CPU Vulkan device (lavapipe: IEEE arithmetic, `precise`, no FMA contraction, the same
//   operations in the same order as the -ffp-contract=off CPU reference): every value bit
//   for bit;
// - any other device (a GPU may contract to FMA or reassociate): at most `ulp_bound` ULPs
//   apart, the distribution printed.
// ISOTOUCH_TEST_GPU_RULE=1 applies the GPU rule on a CPU device too, so the tests that a real
// GPU runs are exercised without one.
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/engine/ulp.h"
#include "isotouch/engine/vk_context.h"

namespace isotouch::test {

/// Default ULP bound for one GPU pass against its reference on a real GPU.
inline constexpr std::uint64_t kGpuUlpBound = 64;

/// True where the GPU and CPU results must agree bit for bit (a CPU device).
inline bool expects_bit_identity(const engine::VulkanContext& ctx) {
  const char* e = std::getenv("ISOTOUCH_TEST_GPU_RULE");
  if (e && std::strcmp(e, "1") == 0) return false;
  return ctx.info().type == "cpu";
}

/// `gpu` against `cpu` (n floats each) under the rule above. Bit identity compares the bits
/// (+0 and -0, NaN payloads differ). Under the GPU bound equal values (+inf and +inf too) and
/// NaN against NaN agree; otherwise at most `ulp_bound` ULPs of the largest finite |cpu|
/// value (an absolute tolerance at the array's scale: a value near zero after cancellation
/// is many of its own ULPs off for the same rounding error).
inline ::testing::AssertionResult gpu_matches_cpu(const engine::VulkanContext& ctx, const float* gpu, const float* cpu,
                                                  std::size_t n, const std::string& what,
                                                  std::uint64_t ulp_bound = kGpuUlpBound) {
  const std::vector<float> a(gpu, gpu + n), b(cpu, cpu + n);
  const engine::UlpStats s = engine::ulp_stats(a, b);
  float scale = 0.f;
  std::size_t bits_differ = 0, first_bits = 0, beyond = 0, first_beyond = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (std::isfinite(b[i])) scale = std::max(scale, std::abs(b[i]));
  const double tol = double(ulp_bound) * double(std::nextafter(scale, INFINITY) - scale);
  for (std::size_t i = 0; i < n; ++i) {
    if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0 && !bits_differ++) first_bits = i;
    // Equal values (equal infinities too: their difference is NaN) and two NaNs (any payload)
    // agree; otherwise the difference must be within the tolerance.
    const bool same = a[i] == b[i] || (std::isnan(a[i]) && std::isnan(b[i]));
    if (!same && !(std::abs(double(a[i]) - double(b[i])) <= tol) && !beyond++) first_beyond = i;
  }
  std::printf("  %-48s %9zu values, %zu differ, ULP max %llu p99 %llu\n", what.c_str(), s.n, bits_differ,
              static_cast<unsigned long long>(s.max), static_cast<unsigned long long>(s.p99));
  const bool exact = expects_bit_identity(ctx);
  if (exact ? bits_differ == 0 : beyond == 0) return ::testing::AssertionSuccess();
  const std::size_t f = exact ? first_bits : first_beyond;
  ::testing::AssertionResult r = ::testing::AssertionFailure();
  r << what << ": " << (exact ? bits_differ : beyond) << " of " << n;
  if (exact) r << " values differ in their bits (bit identity on a CPU device)";
  else r << " values beyond " << ulp_bound << " ULPs of the largest value";
  return r << ", first at " << f << " (GPU " << a[f] << ", CPU " << b[f] << ")";
}

inline ::testing::AssertionResult gpu_matches_cpu(const engine::VulkanContext& ctx, const std::vector<float>& gpu,
                                                  const std::vector<float>& cpu, const std::string& what,
                                                  std::uint64_t ulp_bound = kGpuUlpBound) {
  if (gpu.size() != cpu.size())
    return ::testing::AssertionFailure() << what << ": " << gpu.size() << " GPU values, " << cpu.size() << " CPU values";
  return gpu_matches_cpu(ctx, gpu.data(), cpu.data(), gpu.size(), what, ulp_bound);
}

/// Samples compared as two arrays, each under the rule above with its own scale: the values
/// [value units], and the gradients [value/m] (10^3-10^6 times larger: one scale for both
/// would let a GPU's values drift by thousands of their own ULPs).
inline ::testing::AssertionResult gpu_matches_cpu(const engine::VulkanContext& ctx,
                                                  const std::vector<core::Sample>& gpu,
                                                  const std::vector<core::Sample>& cpu, const std::string& what,
                                                  std::uint64_t ulp_bound = kGpuUlpBound) {
  if (gpu.size() != cpu.size())
    return ::testing::AssertionFailure() << what << ": " << gpu.size() << " GPU samples, " << cpu.size() << " CPU samples";
  std::vector<float> gv, cv, gg, cg;
  gv.reserve(gpu.size()), cv.reserve(cpu.size()), gg.reserve(3 * gpu.size()), cg.reserve(3 * cpu.size());
  for (std::size_t i = 0; i < gpu.size(); ++i) {
    gv.push_back(gpu[i].value), cv.push_back(cpu[i].value);
    for (float x : {gpu[i].gx, gpu[i].gy, gpu[i].gz}) gg.push_back(x);
    for (float x : {cpu[i].gx, cpu[i].gy, cpu[i].gz}) cg.push_back(x);
  }
  ::testing::AssertionResult values = gpu_matches_cpu(ctx, gv, cv, what + " (values)", ulp_bound);
  if (!values) return values;
  return gpu_matches_cpu(ctx, gg, cg, what + " (gradients)", ulp_bound);
}

}  // namespace isotouch::test
