// gradient_pass.h - the "gradient" compute pass: value + gradient per voxel on the GPU.
#pragma once
#include "isotouch/engine/core_names.h"
#include <cstdint>

#include <array>
#include <map>
#include <memory>
#include <vector>

#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/vk_resources.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {

struct GradientTimings {
  double upload_ms = 0;     ///< host copy of the voxels into the mapped staging (upload) buffer
  double gradient_ms = 0;   ///< device time of all dispatches (GPU timestamps), else wall
  double submit_wall_ms = 0;///< wall time from vkQueueSubmit to the fence signalling
  double download_ms = 0;   ///< host copy of the samples out of the mapped readback buffer
  int slabs = 0;            ///< z-slabs dispatched (bindings kept <= max range)
  bool gpu_timestamps = false;
};

/// Computes the plane-ready SampleField of a volume with shaders/gradient.comp.
/// The volume is split into z-slabs so that no storage-buffer binding exceeds
/// maxStorageBufferRange (128 MiB on lavapipe). Voxels go host -> upload buffer ->
/// device-local buffer; samples device-local -> readback buffer -> host, the copies and
/// the dispatches recorded into one command buffer (engine/vk_resources.h).
class GradientPass {
 public:
  explicit GradientPass(VulkanContext& ctx, ShaderSet shaders = ShaderSet::Current);
  ~GradientPass();
  GradientPass(const GradientPass&) = delete;
  GradientPass& operator=(const GradientPass&) = delete;

  /// @param max_binding_bytes if non-zero, a smaller binding limit than the device's
  ///        (tests use it to force many slabs on small volumes).
  /// @throws VolumeError if one z-slice alone exceeds the binding limit.
  core::SampleField run(const Volume& volume, GradientTimings* timings = nullptr,
                         std::uint64_t max_binding_bytes = 0);

  /// The z-slabs of a gradient from a float buffer `src` to a vec4 buffer `dst` of this
  /// grid (the GPU-resident form, for pass chains).
  /// @throws VolumeError naming `what`, the slice size and the limit if a slice does not fit.
  std::vector<Slab> plan(const core::Grid& grid, VkBuffer src, VkBuffer dst, std::uint64_t max_binding_bytes,
                         const std::string& what) const;
  /// What a floor run moves per voxel (shaders/copy_x4.comp's OUT): the gradient's read of
  /// 4 B and write of a 16 B sample; a filter's 4 B read and 4 B written (Gaussian,
  /// closing); brick min/max's 4 B read (its per-brick output is negligible).
  enum class FloorTraffic { Samples = 0, Floats = 1, ReadOnly = 2 };
  /// The floor of this pass on this device: shaders/copy_x4.comp (the same texel loads and
  /// vec4 stores as gradient_x4, no arithmetic) over `volume`, one untimed run and then the
  /// median device time [ms] of `runs` (wall time without timestamps). Buffers device-local.
  /// `traffic`: the loads and stores of another dense pass instead (the chain's floor).
  double copy_floor_ms(const Volume& volume, int runs, FloorTraffic traffic = FloorTraffic::Samples);
  /// Records the dispatches of `slabs` (from plan()); no barriers. One slab of the whole
  /// field (whole_field()) runs shaders/gradient_whole_x4.comp (three descriptors), others
  /// gradient_x4.comp (two per slab).
  void record(VkCommandBuffer cmd, DescriptorArena& arena, const core::Grid& grid,
              const std::vector<Slab>& slabs) const;
  /// Whether record() runs these slabs as one whole-field dispatch: the current shaders, one
  /// slab from offset 0 holding whole quads, nx >= 8, ny and nz >= 2, the field within one
  /// texel view.
  bool whole_field(const core::Grid& grid, const std::vector<Slab>& slabs) const;

 private:
  VulkanContext& ctx_;
  ShaderSet shaders_;
  std::unique_ptr<ComputePipeline<gpu::GradientPush>> legacy_;
  /// gradient_x4 variants by volume size and quad input (specialization constants: nx, ny,
  /// nz, VEC4_IN), made on first use.
  mutable std::map<std::array<int, 4>, std::unique_ptr<ComputePipeline<gpu::DensePush>>> x4_;
  /// gradient_whole_x4 with its specialization (size, inverse spacings), remade when another
  /// grid comes.
  mutable std::unique_ptr<ComputePipeline<gpu::DensePush>> whole_;
  mutable std::vector<std::uint32_t> whole_spec_;
  void record_whole(VkCommandBuffer cmd, DescriptorArena& arena, const core::Grid& grid, const Slab& s) const;
};

}  // namespace isotouch::engine
