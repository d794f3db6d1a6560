// ulp.h - distance between floats in units in the last place, and its distribution over
// two arrays: how far a GPU pass is from its CPU reference (tests/test_passes.cpp,
// `isotouch check --all`). Header only; no state.
#pragma once
#include "isotouch/engine/core_names.h"
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace isotouch::engine {

/// Distance between a and b in ULPs of float: the number of representable floats between
/// them (+0 and -0 are 1 apart, two NaNs are 0 apart, NaN against a number is huge).
inline std::uint64_t ulp_distance(float a, float b) {
  if (std::isnan(a) && std::isnan(b)) return 0;
  auto ord = [](float f) {
    const std::int64_t i = std::bit_cast<std::int32_t>(f);
    return i < 0 ? -(i & 0x7fffffff) : i;
  };
  const std::int64_t d = ord(a) - ord(b);
  return std::uint64_t(d < 0 ? -d : d);
}

/// ULP distribution of a against b (same length).
struct UlpStats {
  std::size_t n = 0;       ///< values compared
  std::size_t differ = 0;  ///< values that are not bit-identical (ulp_distance > 0)
  std::size_t first = 0;   ///< index of the first difference (valid if differ > 0)
  std::uint64_t max = 0;   ///< largest ulp_distance
  std::uint64_t p99 = 0;   ///< 99th percentile of ulp_distance
};

/// @pre a.size() == b.size() (only the common prefix is compared otherwise).
inline UlpStats ulp_stats(const std::vector<float>& a, const std::vector<float>& b) {
  UlpStats s;
  s.n = std::min(a.size(), b.size());
  std::vector<std::uint64_t> d(s.n);
  for (std::size_t i = 0; i < s.n; ++i) {
    d[i] = ulp_distance(a[i], b[i]);
    if (d[i] && !s.differ++) s.first = i;
  }
  if (d.empty()) return s;
  s.max = *std::max_element(d.begin(), d.end());
  const std::size_t k = std::min(d.size() - 1, d.size() * 99 / 100);
  std::nth_element(d.begin(), d.begin() + std::ptrdiff_t(k), d.end());
  s.p99 = d[k];
  return s;
}

}  // namespace isotouch::engine
