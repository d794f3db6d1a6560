// libFuzzer target for the .vdb loader (OpenVDB): any input either loads a float grid into a
// volume within the limits every volume meets (voxels, spacing and extent, origin, an
// orthonormal direction: io::check_volume_limits) or throws VdbError naming the file.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "isotouch/io/vdb_io.h"

namespace {
/// What loaded meets the limits: spacing finite, positive, extent and origin bounded, D orthonormal.
bool within_limits(const isotouch::engine::Volume& v) {
  const auto& g = v.grid;
  const double sp[3] = {g.spacing_m.x, g.spacing_m.y, g.spacing_m.z}, org[3] = {g.origin_m.x, g.origin_m.y, g.origin_m.z};
  for (int a = 0; a < 3; ++a) {
    if (!(sp[a] > 0) || !std::isfinite(sp[a]) || (g.dims[a] - 1) * sp[a] > isotouch::io::kMaxExtentM * (1 + 1e-12))
      return false;
    if (!(std::abs(org[a]) <= isotouch::io::kMaxOriginM * (1 + 1e-12))) return false;
  }
  const auto& D = v.direction;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += D[std::size_t(3 * k + i)] * D[std::size_t(3 * k + j)];
      if (!(std::abs(dot - (i == j ? 1.0 : 0.0)) <= 1e-3)) return false;
    }
  return true;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = "/tmp/isotouch-fuzz-" + std::to_string(::getpid()) + ".vdb";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) __builtin_trap();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) __builtin_trap();
  std::fclose(f);
  // A small limit: the fuzzer looks for the checks, not for big allocations.
  constexpr std::uint64_t kLimit = std::uint64_t(1) << 22;
  try {
    const isotouch::io::LoadedVdb l = isotouch::io::load_vdb(path, "", kLimit);
    const auto& g = l.volume.grid;
    const std::uint64_t n = std::uint64_t(g.dims[0]) * std::uint64_t(g.dims[1]) * std::uint64_t(g.dims[2]);
    if (n != l.volume.voxels.size() || n > kLimit) __builtin_trap();
    if (!within_limits(l.volume)) __builtin_trap();
  } catch (const isotouch::io::VdbError&) {
  }
  std::remove(path.c_str());
  return 0;
}
