// libFuzzer target for the volume loaders (ITK MetaImage / NRRD / NIfTI, teem's NRRD
// fallback): the first byte picks the file kind, the rest is the file. Any input either
// loads a volume whose header checks hold or throws VolumeError naming the file.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "isotouch/engine/volume.h"
#include "isotouch/io/volume_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const char* kinds[] = {".nrrd", ".nhdr", ".mha", ".mhd", ".nii", ".nii.gz"};
  const std::string path = "/tmp/isotouch-fuzz-volume-" + std::to_string(::getpid()) + kinds[data[0] % 6];
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) __builtin_trap();
  if (size > 1 && std::fwrite(data + 1, 1, size - 1, f) != size - 1) __builtin_trap();
  std::fclose(f);
  try {
    const isotouch::engine::Volume v = isotouch::io::load_volume(path);
    const auto& g = v.grid;
    std::uint64_t n = 1;
    for (int a = 0; a < 3; ++a) {
      if (g.dims[a] < 1) __builtin_trap();
      n *= std::uint64_t(g.dims[a]);
    }
    if (n != v.voxels.size() || n > isotouch::io::kMaxVoxels) __builtin_trap();
    if (!(g.spacing_m.x > 0 && g.spacing_m.y > 0 && g.spacing_m.z > 0)) __builtin_trap();
    if (!std::isfinite(g.origin_m.x + g.origin_m.y + g.origin_m.z)) __builtin_trap();
  } catch (const isotouch::engine::VolumeError&) {
  }
  std::remove(path.c_str());
  return 0;
}
