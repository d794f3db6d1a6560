// device_memory.h - the device memory this process holds through engine::GpuBuffer, counted
// at vkAllocateMemory and vkFreeMemory (imported host memory is not counted: it is the
// host's), and the process's memory in one line. On a CPU device (lavapipe) device memory
// is host memory too, part of the resident set.
#pragma once
#include <cstdint>
#include <string>

#include <vulkan/vulkan.h>

namespace isotouch::engine {

struct DeviceMemoryUse {
  std::uint64_t live_bytes = 0;  ///< allocated now [bytes]
  std::uint64_t peak_bytes = 0;  ///< the most allocated at once since the process started [bytes]
  std::uint64_t allocations = 0; ///< allocations live now
};

/// What engine::GpuBuffer holds now and at most (thread-safe).
DeviceMemoryUse device_memory_use();

/// "peak resident set X MiB (now Y MiB); device memory Z MiB now, W MiB at most (N
/// allocations)": /proc/self/status (VmHWM, VmRSS) and device_memory_use().
std::string memory_report();

/// GpuBuffer's bookkeeping: `bytes` allocated as `memory`, and `memory` freed (a handle not
/// counted is ignored).
void count_allocation(VkDeviceMemory memory, std::uint64_t bytes);
void count_free(VkDeviceMemory memory);

}  // namespace isotouch::engine
