// vk_context.h - Vulkan instance, device choice, queue, command submission.
// Resources (buffers, pipelines, barriers) live in vk_resources.h: the context owns
// no memory of its own beyond its command pool and fence.
#pragma once
#include "isotouch/engine/core_names.h"
#include <vulkan/vulkan.h>

#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/engine/result.h"

namespace isotouch::engine {

/// Thrown by VK_CHECK: a Vulkan call that cannot fail in a correct program failed.
struct VulkanError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

[[noreturn]] void vk_check_failed(const char* call, VkResult r, const char* file, int line);
const char* vk_result_name(VkResult r);

/// Tier-1 errors: prints/throws with file:line, the call and the VkResult name.
#define VK_CHECK(call)                                                            \
  do {                                                                            \
    const VkResult vk_check_result_ = (call);                                     \
    if (vk_check_result_ != VK_SUCCESS)                                           \
      ::isotouch::engine::vk_check_failed(#call, vk_check_result_, __FILE__, __LINE__); \
  } while (0)


struct ContextOptions {
  /// Case-insensitive substring of the device name, or a device index ("0", "1").
  /// Empty: the ISOTOUCH_DEVICE environment variable, else the first discrete GPU,
  /// integrated GPU, virtual GPU, then CPU (lavapipe) device.
  std::string device;
  /// Enable VK_LAYER_KHRONOS_validation and count its messages (also with
  /// ISOTOUCH_VALIDATION=1). Fails set-up if the layer is not installed.
  bool validation = false;
  /// With `validation`: also enable the layer's synchronization validation
  /// (VK_EXT_validation_features), which reports missing or wrong barriers as hazards.
  /// Ignored (no error) if the layer does not offer VK_EXT_validation_features.
  bool synchronization_validation = false;
  /// Extra instance extensions (a window system's, e.g. what glfwGetRequiredInstanceExtensions
  /// names). Empty: the headless instance as before. Set-up fails naming a missing one.
  std::vector<std::string> instance_extensions;
  /// Enable VK_KHR_swapchain on the device (a window presents); set-up fails if the chosen
  /// device lacks it. False: the headless device as before.
  bool swapchain = false;
};

struct DeviceInfo {
  std::string name;
  std::string type;  ///< "discrete-gpu", "integrated-gpu", "virtual-gpu", "cpu", "other"
  std::string driver;
  std::uint32_t api_version = 0;
};

class VulkanContext {
 public:
  static Result<std::unique_ptr<VulkanContext>> create(const ContextOptions& options = {});
  /// All physical devices, for `isotouch devices`.
  static Result<std::vector<DeviceInfo>> list_devices();
  ~VulkanContext();
  VulkanContext(const VulkanContext&) = delete;
  VulkanContext& operator=(const VulkanContext&) = delete;

  VkInstance instance() const { return instance_; }
  VkDevice device() const { return device_; }
  VkQueue queue() const { return queue_; }
  std::uint32_t queue_family() const { return family_; }
  const VkPhysicalDeviceProperties& properties() const { return props_; }
  const DeviceInfo& info() const { return info_; }
  bool timestamps_supported() const { return timestamp_bits_ > 0; }

  VkPhysicalDevice physical_device() const { return phys_; }
  const VkPhysicalDeviceMemoryProperties& memory_properties() const { return mem_props_; }
  /// Largest single VkDeviceMemory allocation [bytes] (VkPhysicalDeviceMaintenance3Properties).
  VkDeviceSize max_allocation_bytes() const { return max_allocation_; }
  /// Largest storage-buffer binding [bytes] (limits.maxStorageBufferRange).
  VkDeviceSize max_binding_bytes() const { return props_.limits.maxStorageBufferRange; }

  /// True if every device-local memory type is also host-visible and coherent (lavapipe,
  /// integrated GPUs) and zero copy is allowed: device-local buffers are then mapped, the
  /// host writes inputs and reads outputs in place, and no staging or readback copy runs.
  bool device_local_is_host_visible() const { return unified_memory_ && zero_copy_; }
  /// Turns zero copy off (staging and readback copies as on a discrete GPU), for tests and
  /// for `bench engine`'s comparison. Affects buffers created afterwards.
  void allow_zero_copy(bool allow) { zero_copy_ = allow; }

  /// VK_EXT_external_memory_host is enabled (lavapipe offers it): host memory can be
  /// imported as a buffer without a copy (GpuBuffer::import_host). Its pointer and size
  /// must be multiples of host_import_alignment() bytes; 0 where it is not offered.
  VkDeviceSize host_import_alignment() const { return host_import_ ? host_import_alignment_ : 0; }
  /// Turns host-memory import off (inputs copied as before), for tests and comparisons.
  void allow_host_import(bool allow) { host_import_ = allow; }

  VkCommandBuffer begin_commands();
  /// Submit, wait on a fence; returns the wall time from submit to signal [ms].
  double submit_and_wait(VkCommandBuffer cmd);
  /// submit_and_wait() with `meanwhile` run on this thread between the submit and the wait
  /// (host work that needs neither this context's queue nor its fence): on a CPU device
  /// it runs while the device's threads work instead of after them. Returns the wall time
  /// from the submit to the later of the fence and `meanwhile`'s end [ms]. If it throws, the
  /// submission is waited for and the exception passed on.
  double submit_and_wait(VkCommandBuffer cmd, const std::function<void()>& meanwhile);

  /// Validation messages of severity warning or error seen so far.
  std::uint32_t validation_messages() const { return validation_count_.load(); }

 private:
  VulkanContext() = default;
  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkPhysicalDevice phys_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  std::uint32_t family_ = 0;
  std::uint32_t timestamp_bits_ = 0;
  VkPhysicalDeviceProperties props_{};
  VkPhysicalDeviceMemoryProperties mem_props_{};
  VkDeviceSize max_allocation_ = 0;
  bool unified_memory_ = false;
  bool zero_copy_ = true;
  VkDeviceSize host_import_alignment_ = 0;
  bool host_import_ = true;
  DeviceInfo info_;
  std::atomic<std::uint32_t> validation_count_{0};

  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                   VkDebugUtilsMessageTypeFlagsEXT,
                                                   const VkDebugUtilsMessengerCallbackDataEXT*,
                                                   void*);
};

}  // namespace isotouch::engine
