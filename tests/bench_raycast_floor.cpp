// bench_raycast_floor - the floor of a ray-caster frame on this Vulkan device, beside the
// ray caster's own figures (isotouch-sculpt --bench, isotouch bench render): passes that
// only store one uint per pixel of a W x H frame after F texel fetches of voxel values
// (shaders/raycast_floor.comp), F = 0 (the store alone), 8 (one trilinear sample), 27 (the
// shade pass's refinement block), 64 and 128. GPU timestamps, median of the frames.
// Usage: bench_raycast_floor [WIDTH HEIGHT FRAMES]
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "isotouch/shaders/raycast_floor_spv.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/vk_resources.h"

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
  constexpr std::uint32_t kVoxels = 1u << 18;  // 1 MiB of floats, about the head CT's 381k voxels
  std::vector<float> vals(kVoxels);
  for (std::uint32_t i = 0; i < kVoxels; ++i) vals[i] = float(i % 1000);
  engine::GpuBuffer up = engine::make_buffer_or_throw(vk, kVoxels * 4, engine::MemoryIntent::Upload, "floor values staging");
  engine::GpuBuffer v = engine::make_buffer_or_throw(vk, kVoxels * 4, engine::MemoryIntent::DeviceLocal, "floor values");
  const std::size_t pixels = std::size_t(width) * std::size_t(height);
  engine::GpuBuffer out = engine::make_buffer_or_throw(vk, pixels * 4, engine::MemoryIntent::DeviceLocal, "floor image");
  std::memcpy(up.mapped(), vals.data(), kVoxels * 4);
  VkCommandBuffer cmd = vk.begin_commands();
  engine::record_copy(cmd, up, v, kVoxels * 4);
  engine::barrier_transfer_to_compute(cmd);
  vk.submit_and_wait(cmd);
  std::printf("bench_raycast_floor: %d x %d frame, one invocation per pixel (rows of %u), %s, median of %d frames\n\n",
              width, height, unsigned(ISOTOUCH_RAYCAST_WG_X), vk.info().name.c_str(), frames);
  std::printf("| texel fetches per pixel | texel | ms per frame | ns per pixel |\n|---:|---|---:|---:|\n");
  engine::DescriptorArena arena(vk, 2, 4);
  engine::GpuTimer timer(vk, 2);
  struct Case {
    std::uint32_t fetches;
    bool vec4;
  };
  for (const Case cs : {Case{0, false}, Case{2, true}, Case{8, false}, Case{8, true}, Case{27, false}, Case{64, false},
                        Case{64, true}, Case{128, false}}) {
    const std::uint32_t f = cs.fetches;
    engine::ComputePipeline<gpu::RaycastFloorPush> pipe(vk, raycast_floor_spv, 2, "raycast floor", 0u,
                                                        {f, (cs.vec4 ? kVoxels / 4 : kVoxels) - 1, cs.vec4 ? 1u : 0u}, 1u);
    if (cs.vec4) pipe.set_texel_vec4(1u);
    std::vector<double> ms;
    for (int k = 0; k <= frames; ++k) {
      arena.reset();
      VkCommandBuffer cb = vk.begin_commands();
      timer.record_reset(cb);
      pipe.bind(cb, arena, {{v.handle(), 0, v.size()}, {out.handle(), 0, pixels * 4}});
      pipe.push(cb, gpu::RaycastFloorPush{std::uint32_t(width), std::uint32_t(height), 0, 0});
      timer.mark(cb, 0);
      vkCmdDispatch(cb, (std::uint32_t(width) + ISOTOUCH_RAYCAST_WG_X - 1) / ISOTOUCH_RAYCAST_WG_X, std::uint32_t(height), 1);
      timer.mark(cb, 1);
      const double wall = vk.submit_and_wait(cb);
      const double t = timer.elapsed_ms(0, 1);
      if (k > 0) ms.push_back(t >= 0 ? t : wall);  // frame 0: warm-up
    }
    std::sort(ms.begin(), ms.end());
    const double med = ms[ms.size() / 2];
    std::printf("| %u | %s | %.2f | %.1f |\n", f, cs.vec4 ? "4 floats" : "1 float", med, med * 1e6 / double(pixels));
  }
  return 0;
}
