// live_gpu_none.cpp - the live field's GPU recompute in a build without Vulkan (the
// ThreadSanitizer preset): it cannot be made, so the live field recomputes on the CPU.
#include "isotouch/session/live_gpu.h"

namespace isotouch::session {

engine::Result<std::unique_ptr<LiveGpuFilter>> make_live_gpu_filter(engine::VulkanContext&, const engine::Volume& vol,
                                                                     const std::vector<engine::PassDesc>&) {
  return engine::Result<std::unique_ptr<LiveGpuFilter>>::fail(vol.path +
                                                               ": this build of isotouch has no Vulkan: no GPU recompute");
}

}  // namespace isotouch::session
