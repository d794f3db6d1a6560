#include "isotouch/engine/device_memory.h"

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <mutex>
#include <sstream>
#include <unordered_map>

namespace isotouch::engine {

namespace {
/// Device memory allocated through GpuBuffer::create, by allocation.
struct MemoryCount {
  std::mutex mu;
  std::unordered_map<VkDeviceMemory, std::uint64_t> bytes;
  std::uint64_t live = 0, peak = 0;
};
MemoryCount& memory_count() {
  static MemoryCount c;
  return c;
}

/// A "Key:   N kB" line of /proc/self/status [bytes]; 0 if absent.
std::uint64_t status_bytes(const std::string& key) {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind(key, 0) == 0) return std::uint64_t(std::stoull(line.substr(key.size()))) * 1024;
  return 0;
}

std::string mib(std::uint64_t bytes) {
  std::ostringstream o;
  o << std::fixed << std::setprecision(0) << double(bytes) / (1024.0 * 1024.0) << " MiB";
  return o.str();
}
}  // namespace

void count_allocation(VkDeviceMemory memory, std::uint64_t bytes) {
  MemoryCount& c = memory_count();
  std::lock_guard<std::mutex> lock(c.mu);
  c.bytes[memory] = bytes;
  c.live += bytes;
  c.peak = std::max(c.peak, c.live);
}

void count_free(VkDeviceMemory memory) {
  MemoryCount& c = memory_count();
  std::lock_guard<std::mutex> lock(c.mu);
  const auto it = c.bytes.find(memory);
  if (it == c.bytes.end()) return;  // imported host memory: not counted
  c.live -= it->second;
  c.bytes.erase(it);
}

DeviceMemoryUse device_memory_use() {
  MemoryCount& c = memory_count();
  std::lock_guard<std::mutex> lock(c.mu);
  return {c.live, c.peak, std::uint64_t(c.bytes.size())};
}

std::string memory_report() {
  const DeviceMemoryUse d = device_memory_use();
  return "peak resident set " + mib(status_bytes("VmHWM:")) + " (now " + mib(status_bytes("VmRSS:")) +
         "); device memory " + mib(d.live_bytes) + " now, " + mib(d.peak_bytes) + " at most (" +
         std::to_string(d.allocations) + " allocations)";
}

}  // namespace isotouch::engine
