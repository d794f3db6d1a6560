// libFuzzer target for the .vdb loader (OpenVDB): any input either loads a float grid into a
// volume within the voxel limit or throws VdbError naming the file.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "vdb_io.h"

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
  } catch (const isotouch::io::VdbError&) {
  }
  std::remove(path.c_str());
  return 0;
}
