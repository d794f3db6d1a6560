// bench_raycast_floor - the floor of a ray-caster frame on this Vulkan device, beside the
// ray caster's own figures (isotouch-sculpt --bench, isotouch bench render): passes that
// only store one uint per pixel of a W x H frame after F texel fetches of voxel values
// (shaders/raycast_floor.comp, engine::raycast_floor), F = 0 (the store alone), 8 (one trilinear sample), 27 (the
// shade pass's refinement block), 64 and 128. GPU timestamps, median of the frames.
// Usage: bench_raycast_floor [WIDTH HEIGHT FRAMES]
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/raycast.h"

using namespace isotouch;

int main(int argc, char** argv) {
  const int width = argc > 2 ? std::atoi(argv[1]) : 1024, height = argc > 2 ? std::atoi(argv[2]) : 768;
  const int frames = argc > 3 ? std::atoi(argv[3]) : 9;
  if (width < 1 || height < 1 || frames < 1) {
    std::fprintf(stderr, "usage: bench_raycast_floor [WIDTH HEIGHT FRAMES]\n");
    return 1;
  }
  auto c = engine::VulkanContext::create(engine::ContextOptions{});
  if (!c) {
    std::fprintf(stderr, "bench_raycast_floor: Vulkan: %s\n", c.error.c_str());
    return 1;
  }
  engine::VulkanContext& vk = **c.value;
  std::printf("bench_raycast_floor: %d x %d frame, one invocation per pixel (rows of %u), %s, median of %d frames\n\n",
              width, height, unsigned(ISOTOUCH_RAYCAST_WG_X), vk.info().name.c_str(), frames);
  std::printf("| texel fetches per pixel | texel | ms per frame | ns per pixel |\n|---:|---|---:|---:|\n");
  struct Case {
    std::uint32_t fetches;
    bool vec4;
  };
  const double pixels = double(width) * double(height);
  for (const Case cs : {Case{0, false}, Case{2, true}, Case{8, false}, Case{8, true}, Case{27, false}, Case{64, false},
                        Case{64, true}, Case{128, false}}) {
    const double med = engine::raycast_floor(vk, width, height, cs.fetches, cs.vec4, frames).gpu_ms;
    std::printf("| %u | %s | %.2f | %.1f |\n", cs.fetches, cs.vec4 ? "4 floats" : "1 float", med, med * 1e6 / pixels);
  }
  return 0;
}
