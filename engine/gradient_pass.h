// gradient_pass.h - the "gradient" compute pass: value + gradient per voxel on the GPU.
#pragma once
#include <cstdint>

#include "sample_field.h"
#include "vk_context.h"
#include "volume.h"

namespace isotouch::engine {

struct GradientTimings {
  double upload_ms = 0;     ///< host copy of the voxels into the mapped src buffer
  double gradient_ms = 0;   ///< device time of all dispatches (GPU timestamps), else wall
  double submit_wall_ms = 0;///< wall time from vkQueueSubmit to the fence signalling
  double download_ms = 0;   ///< host copy of the samples out of the mapped dst buffer
  int slabs = 0;            ///< z-slabs dispatched (bindings kept <= max range)
  bool gpu_timestamps = false;
};

/// Computes the plane-ready SampleField of a volume with shaders/gradient.comp.
/// The volume is split into z-slabs so that no storage-buffer binding exceeds
/// maxStorageBufferRange (128 MiB on lavapipe).
class GradientPass {
 public:
  explicit GradientPass(VulkanContext& ctx);
  ~GradientPass();
  GradientPass(const GradientPass&) = delete;
  GradientPass& operator=(const GradientPass&) = delete;

  /// @param max_binding_bytes if non-zero, a smaller binding limit than the device's
  ///        (tests use it to force many slabs on small volumes).
  /// @throws VolumeError if one z-slice alone exceeds the binding limit.
  servo::SampleField run(const Volume& volume, GradientTimings* timings = nullptr,
                         std::uint64_t max_binding_bytes = 0);

 private:
  VulkanContext& ctx_;
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout layout_ = VK_NULL_HANDLE;
  VkPipeline pipeline_ = VK_NULL_HANDLE;
  VkShaderModule module_ = VK_NULL_HANDLE;
};

}  // namespace isotouch::engine
