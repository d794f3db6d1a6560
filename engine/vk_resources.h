// vk_resources.h - buffers with a memory intent, staging, compute pipelines, barriers.
//
// The layer the compute passes stand on. Nothing here assumes that
// device memory is host-visible: compute passes read and write DeviceLocal buffers, the
// host writes Upload buffers and reads Readback buffers, and copies between them are
// recorded into the same command buffer as the passes (record_copy + the barriers below).
// On a discrete GPU they are the PCIe transfers they must be. Where every device-local
// memory type is host-visible and coherent (lavapipe, integrated GPUs) a DeviceLocal buffer
// is also mapped, and passes that check VulkanContext::device_local_is_host_visible()
// write their inputs and read their outputs in place: no staging, no readback copy.
//
// Errors: set-up that can fail on a correct program (a buffer larger than the device's
// maxMemoryAllocationSize, no memory type of the intent, out of memory) returns a Result
// whose error names what, the size and the limit; calls that cannot fail use VK_CHECK.
#pragma once
#include "isotouch/engine/core_names.h"
#include <vulkan/vulkan.h>

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/engine/vk_context.h"

namespace isotouch::engine {

/// Which shaders a dense pass runs: Current, shaped for llvmpipe and real GPUs alike
/// (texel-buffer input, 4 voxels per invocation, 1-D workgroups, specialised constants:
/// gradient_x4.comp, gaussian_x4.comp), or Legacy (one voxel per invocation, storage-buffer
/// loads, 8x8x4 workgroups: gradient.comp, gaussian1d.comp), kept for `bench engine`'s
/// side-by-side comparison. Both give the same bits.
enum class ShaderSet { Current, Legacy };
const char* shader_set_name(ShaderSet s);

/// The memory type for a resource: among `bits` (VkMemoryRequirements::memoryTypeBits), one
/// with every flag of `want` on a heap of at least `bytes`, the first that also has every
/// flag of `prefer` if any does, else the first; none if no type has `want`.
std::optional<std::uint32_t> find_memory(const VkPhysicalDeviceMemoryProperties& mp, std::uint32_t bits,
                                         VkMemoryPropertyFlags want, VkMemoryPropertyFlags prefer,
                                         VkDeviceSize bytes);

/// What a buffer is for; decides its memory type and usage flags.
enum class MemoryIntent {
  DeviceLocal,  ///< read/written by shaders; copy source and destination; indirect dispatch
                ///< arguments; mapped only where device-local memory is host-visible
                ///< (VulkanContext::device_local_is_host_visible: zero copy)
  Upload,       ///< host-visible, coherent, mapped: host writes, GPU copies out (staging)
  Readback,     ///< host-visible, coherent (cached if offered), mapped: GPU copies in, host reads
};
const char* intent_name(MemoryIntent intent);

/// One VkBuffer with its own VkDeviceMemory. Move-only; the destructor destroys the buffer
/// first and then frees (after unmapping) its memory, the order the Vulkan spec requires
/// for memory still bound to a live buffer.
class GpuBuffer {
 public:
  GpuBuffer() = default;
  /// @param what a name for error messages ("volume", "samples", ...).
  /// Fails (no throw) if `bytes` is 0, exceeds maxMemoryAllocationSize, no memory type
  /// fits the intent, or the allocation fails; the error names what, size and limit.
  static Result<GpuBuffer> create(VulkanContext& ctx, VkDeviceSize bytes, MemoryIntent intent,
                                  const std::string& what);
  /// The host memory [p, p + bytes) as a buffer the shaders read in place, without a copy
  /// (VK_EXT_external_memory_host; VulkanContext::host_import_alignment() > 0). The pages
  /// holding the range are imported: the buffer starts at `p` rounded down to the
  /// alignment, and `offset` receives where `p` lies in it. The memory must stay allocated,
  /// and unchanged while work that reads it runs, until the buffer is reset. Storage and
  /// texel-buffer reads, copy source. Fails (no throw) where import is not offered or the
  /// driver refuses the pointer; the error names what.
  static Result<GpuBuffer> import_host(VulkanContext& ctx, const void* p, VkDeviceSize bytes,
                                       const std::string& what, VkDeviceSize& offset);
  ~GpuBuffer() { reset(); }
  GpuBuffer(GpuBuffer&& o) noexcept { *this = std::move(o); }
  GpuBuffer& operator=(GpuBuffer&& o) noexcept;
  GpuBuffer(const GpuBuffer&) = delete;
  GpuBuffer& operator=(const GpuBuffer&) = delete;

  void reset();
  VkBuffer handle() const { return buffer_; }
  VkDeviceSize size() const { return size_; }
  MemoryIntent intent() const { return intent_; }
  /// Host pointer of an Upload or Readback buffer, or of a DeviceLocal one where device-local
  /// memory is host-visible (coherent: no flush needed); null otherwise.
  void* mapped() const { return mapped_; }
  explicit operator bool() const { return buffer_ != VK_NULL_HANDLE; }

 private:
  VkDevice device_ = VK_NULL_HANDLE;
  VkBuffer buffer_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  VkDeviceSize size_ = 0;
  MemoryIntent intent_ = MemoryIntent::DeviceLocal;
  void* mapped_ = nullptr;
};

/// create() that throws VulkanError with the Result's message, for callers that report
/// set-up failures by exception.
GpuBuffer make_buffer_or_throw(VulkanContext& ctx, VkDeviceSize bytes, MemoryIntent intent,
                               const std::string& what);

/// Records a buffer-to-buffer copy of `bytes` (offsets 0).
void record_copy(VkCommandBuffer cmd, const GpuBuffer& src, const GpuBuffer& dst, VkDeviceSize bytes);

// Barriers: global memory barriers (buffers only; no images in this engine).
/// A dispatch's storage writes become visible to the next dispatch's reads and writes.
void barrier_compute_to_compute(VkCommandBuffer cmd);
/// A dispatch's storage writes become visible to a following vkCmdDispatchIndirect's
/// arguments and to its shader.
void barrier_compute_to_indirect(VkCommandBuffer cmd);
/// A transfer (staging copy) becomes visible to the following dispatches (storage and
/// uniform reads).
void barrier_transfer_to_compute(VkCommandBuffer cmd);
/// Dispatch writes become visible to a following copy (to a Readback buffer).
void barrier_compute_to_transfer(VkCommandBuffer cmd);
/// A dispatch's writes to a mapped (zero-copy) buffer become visible to the host after the fence.
void barrier_compute_to_host(VkCommandBuffer cmd);
/// Copies into Readback buffers become visible to the host after the fence.
void barrier_transfer_to_host(VkCommandBuffer cmd);

/// A storage-buffer range bound at one binding of a descriptor set.
struct BufferRange {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceSize offset = 0;
  VkDeviceSize range = 0;
};

/// Descriptor sets for one recording: a pool sized for `max_sets` sets of storage
/// buffers; freed with the arena (after the command buffer has completed).
class DescriptorArena {
 public:
  DescriptorArena(VulkanContext& ctx, std::uint32_t max_sets, std::uint32_t max_buffers);
  ~DescriptorArena();
  DescriptorArena(const DescriptorArena&) = delete;
  DescriptorArena& operator=(const DescriptorArena&) = delete;
  VkDescriptorSet allocate(VkDescriptorSetLayout layout);
  /// A buffer view (texel-buffer binding) that lives as long as the arena's sets: destroyed
  /// by reset() and the destructor, after the command buffer that used it has completed.
  VkBufferView make_view(const BufferRange& r, VkFormat format);
  /// Returns every set to the pool (vkResetDescriptorPool) and destroys the views: reuse the
  /// arena for the next submission once the previous one has completed (its fence waited on).
  void reset();
  std::uint32_t max_sets() const { return max_sets_; }

 private:
  VkDevice device_;
  std::uint32_t max_sets_ = 1;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
  std::vector<VkBufferView> views_;
};

/// A compute pipeline over `bindings` buffers (binding i = i-th BufferRange given to bind())
/// and one push-constant block of `push_bytes`. Use ComputePipeline<Push>. Every binding is
/// a storage buffer except those whose bit is set in `uniform_bindings` (bit i: binding i is
/// a uniform buffer: per-dispatch parameters every invocation reads; on llvmpipe a uniform
/// load at a constant offset is one scalar load, a storage load a per-lane gather).
/// `spec`: specialization constants, constant_id i = spec[i] (32-bit each; a GLSL bool is
/// 0 or 1): a variant of one shader with the code it does not need folded away.
/// `texel_bindings` (bit i): binding i is a uniform texel buffer of R32_SFLOAT (GLSL
/// `samplerBuffer`, read with texelFetch; on llvmpipe a texel fetch takes the gather path,
/// a storage-buffer load a per-lane loop with a bounds check); bind() makes its view.
class ComputePipelineBase {
 public:
  ComputePipelineBase(VulkanContext& ctx, const std::uint32_t* spirv, std::size_t spirv_bytes,
                      std::uint32_t bindings, std::uint32_t push_bytes, std::string name,
                      std::uint32_t uniform_bindings = 0, std::vector<std::uint32_t> spec = {},
                      std::uint32_t texel_bindings = 0);
  ~ComputePipelineBase();
  ComputePipelineBase(const ComputePipelineBase&) = delete;
  ComputePipelineBase& operator=(const ComputePipelineBase&) = delete;

  /// Binds the pipeline and a fresh descriptor set with these buffer ranges.
  /// @throws std::logic_error if the count differs from `bindings` or a range exceeds
  ///         maxStorageBufferRange (callers plan their slabs so this cannot happen).
  void bind(VkCommandBuffer cmd, DescriptorArena& arena, std::initializer_list<BufferRange> buffers) const;
  /// Binds only the pipeline: the descriptor set last bound stays bound where this pipeline's
  /// layout is defined as that set's pipeline's was (Vulkan's layout compatibility: the same
  /// bindings, types and push constant range), e.g. another specialization of one shader.
  void bind_keeping_set(VkCommandBuffer cmd) const;
  /// Bit i: texel binding i is viewed as R32G32B32A32_SFLOAT (texel q = floats 4 q .. 4 q + 3:
  /// one fetch per quad) instead of R32_SFLOAT. Its ranges must be multiples of 16 bytes.
  void set_texel_vec4(std::uint32_t mask) { texel_vec4_ = mask; }
  /// Bit i: texel binding i is viewed as R32G32B32A32_UINT (4 words per texel, their bits as
  /// stored: a struct of 4-byte fields read by texelFetch). Its ranges must be multiples of 16 bytes.
  void set_texel_uint4(std::uint32_t mask) { texel_uint4_ = mask; }
  std::uint32_t bindings() const { return bindings_; }
  const std::string& name() const { return name_; }

 protected:
  void push_bytes(VkCommandBuffer cmd, const void* data) const;

 private:
  VulkanContext& ctx_;
  std::string name_;
  std::uint32_t bindings_ = 0;
  std::uint32_t push_size_ = 0;
  std::uint32_t uniform_ = 0;  ///< bit i: binding i is a uniform buffer
  std::uint32_t texel_ = 0;    ///< bit i: binding i is a uniform texel buffer (R32_SFLOAT)
  std::uint32_t texel_vec4_ = 0;  ///< bit i: that texel buffer's view is R32G32B32A32_SFLOAT
  std::uint32_t texel_uint4_ = 0;  ///< bit i: that texel buffer's view is R32G32B32A32_UINT
  VkDescriptorType descriptor_type(std::uint32_t i) const {
    if ((texel_ >> i) & 1u) return VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
    return (uniform_ >> i) & 1u ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
  }
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout layout_ = VK_NULL_HANDLE;
  VkShaderModule module_ = VK_NULL_HANDLE;
  VkPipeline pipeline_ = VK_NULL_HANDLE;
};

/// Typed push constants: Push is the struct from shaders/isotouch_shared.h.
template <class Push>
class ComputePipeline : public ComputePipelineBase {
 public:
  template <std::size_t N>
  ComputePipeline(VulkanContext& ctx, const std::uint32_t (&spirv)[N], std::uint32_t bindings,
                  std::string name, std::uint32_t uniform_bindings = 0, std::vector<std::uint32_t> spec = {},
                  std::uint32_t texel_bindings = 0)
      : ComputePipelineBase(ctx, spirv, sizeof(spirv), bindings, sizeof(Push), std::move(name), uniform_bindings,
                            std::move(spec), texel_bindings) {}
  void push(VkCommandBuffer cmd, const Push& p) const { push_bytes(cmd, &p); }
};

/// GPU timestamps around the passes of one command buffer (none if unsupported).
class GpuTimer {
 public:
  GpuTimer(VulkanContext& ctx, std::uint32_t max_marks);
  ~GpuTimer();
  GpuTimer(const GpuTimer&) = delete;
  GpuTimer& operator=(const GpuTimer&) = delete;
  bool enabled() const { return pool_ != VK_NULL_HANDLE; }
  /// Resets the pool; record before the first mark.
  void record_reset(VkCommandBuffer cmd);
  /// Writes timestamp number `i` once all previously recorded commands have completed.
  void mark(VkCommandBuffer cmd, std::uint32_t i);
  /// After the fence: milliseconds between marks a and b, or -1 if unavailable.
  double elapsed_ms(std::uint32_t a, std::uint32_t b) const;

 private:
  VulkanContext& ctx_;
  VkQueryPool pool_ = VK_NULL_HANDLE;
  std::uint32_t count_ = 0;
};

/// One dispatch's z-slab: slices [z0, z0 + nz) of the output, reading source slices
/// [src_z0, src_z1) (the slab plus its halo, clamped to the volume). Bindings start at an
/// offset aligned to minStorageBufferOffsetAlignment; *_offset_elems are the elements
/// between the binding start and the first element the shader uses.
struct Slab {
  std::uint64_t z0 = 0, nz = 0, src_z0 = 0, src_z1 = 0;
  BufferRange src, dst;
  std::uint64_t src_offset_elems = 0, dst_offset_elems = 0;
};

/// How a pass maps z-slices onto its source and destination buffers.
struct SlabGeometry {
  std::uint64_t nz = 0;                  ///< slices in the volume
  std::uint64_t src_bytes_per_slice = 0; ///< source bytes per z-slice
  std::uint64_t src_elem_bytes = 4;
  std::uint64_t halo = 0;                ///< source slices needed on each side
  std::uint64_t z_multiple = 1;          ///< slab starts and sizes are multiples of this
  /// Destination bytes before slice z (z a multiple of z_multiple, or nz): offset into dst.
  std::uint64_t (*dst_bytes_before)(std::uint64_t z, const void* user) = nullptr;
  const void* user = nullptr;
  std::uint64_t dst_elem_bytes = 4;
  std::uint32_t wg_z = 1;                ///< workgroup size in z (of slices, or of z_multiple units)
};

/// Whether every slab's source binding holds whole quads of voxels from its first slice on:
/// rows of `nx` (a multiple of 4) voxels, offsets and ranges multiples of 16 bytes - the
/// shaders may then read the source as an R32G32B32A32_SFLOAT texel buffer (one fetch per
/// quad; ComputePipelineBase::set_texel_vec4).
bool slabs_hold_quads(int nx, const std::vector<Slab>& slabs);

/// Splits a pass into z-slabs so that no binding exceeds `limit` bytes (and no dispatch
/// exceeds maxComputeWorkGroupCount[2]).
/// @return empty Result with an error naming `what`, the slice size and the limit if one
///         slab of z_multiple slices (plus halo) does not fit.
Result<std::vector<Slab>> plan_slabs(const VulkanContext& ctx, const SlabGeometry& g, VkBuffer src,
                                     VkBuffer dst, std::uint64_t limit, const std::string& what);

}  // namespace isotouch::engine
