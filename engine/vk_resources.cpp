#include "isotouch/engine/vk_resources.h"
#include "isotouch/engine/device_memory.h"

#include <algorithm>
#include <optional>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <vector>

namespace isotouch::engine {

const char* intent_name(MemoryIntent i) {
  switch (i) {
    case MemoryIntent::DeviceLocal: return "device-local";
    case MemoryIntent::Upload: return "upload";
    case MemoryIntent::Readback: return "readback";
  }
  return "?";
}

std::optional<std::uint32_t> find_memory(const VkPhysicalDeviceMemoryProperties& mp, std::uint32_t bits,
                                         VkMemoryPropertyFlags want, VkMemoryPropertyFlags prefer,
                                         VkDeviceSize bytes) {
  std::optional<std::uint32_t> fallback;
  for (std::uint32_t i = 0; i < mp.memoryTypeCount; ++i) {
    if (!(bits & (1u << i))) continue;
    const auto f = mp.memoryTypes[i].propertyFlags;
    if ((f & want) != want) continue;
    if (mp.memoryHeaps[mp.memoryTypes[i].heapIndex].size < bytes) continue;
    if ((f & prefer) == prefer) return i;
    if (!fallback) fallback = i;
  }
  return fallback;
}

Result<GpuBuffer> GpuBuffer::create(VulkanContext& ctx, VkDeviceSize bytes, MemoryIntent intent,
                                    const std::string& what) {
  using R = Result<GpuBuffer>;
  const std::string name = std::string(intent_name(intent)) + " buffer '" + what + "'";
  if (bytes == 0) return R::fail(name + ": size 0 bytes");
  if (bytes > ctx.max_allocation_bytes())
    return R::fail(name + ": " + std::to_string(bytes) + " bytes exceed maxMemoryAllocationSize " +
                   std::to_string(ctx.max_allocation_bytes()) + " bytes on " + ctx.info().name);
  GpuBuffer b;
  b.device_ = ctx.device();
  b.size_ = bytes;
  b.intent_ = intent;
  VkBufferCreateInfo bi{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  bi.size = bytes;
  VkMemoryPropertyFlags want = 0, prefer = 0;
  switch (intent) {
    case MemoryIntent::DeviceLocal:
      bi.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
                 VK_BUFFER_USAGE_TRANSFER_DST_BIT | VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT |
                 VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT;
      want = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
      if (ctx.device_local_is_host_visible())
        want |= VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
      break;
    case MemoryIntent::Upload:
      bi.usage = VK_BUFFER_USAGE_TRANSFER_SRC_BIT;
      want = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
      break;
    case MemoryIntent::Readback:
      bi.usage = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
      want = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
      prefer = VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
      break;
  }
  bi.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VK_CHECK(vkCreateBuffer(b.device_, &bi, nullptr, &b.buffer_));
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(b.device_, b.buffer_, &req);
  const auto type = find_memory(ctx.memory_properties(), req.memoryTypeBits, want, prefer, req.size);
  if (!type)
    return R::fail(name + ": no memory type for " + std::to_string(req.size) + " bytes on " + ctx.info().name);
  VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  ai.allocationSize = req.size;
  ai.memoryTypeIndex = *type;
  const VkResult r = vkAllocateMemory(b.device_, &ai, nullptr, &b.memory_);
  if (r != VK_SUCCESS)
    return R::fail(name + ": vkAllocateMemory of " + std::to_string(req.size) + " bytes failed: " +
                   vk_result_name(r));
  count_allocation(b.memory_, req.size);
  VK_CHECK(vkBindBufferMemory(b.device_, b.buffer_, b.memory_, 0));
  if (intent != MemoryIntent::DeviceLocal || ctx.device_local_is_host_visible())
    VK_CHECK(vkMapMemory(b.device_, b.memory_, 0, VK_WHOLE_SIZE, 0, &b.mapped_));
  return R::ok(std::move(b));
}

Result<GpuBuffer> GpuBuffer::import_host(VulkanContext& ctx, const void* p, VkDeviceSize bytes,
                                         const std::string& what, VkDeviceSize& offset) {
  using R = Result<GpuBuffer>;
  const std::string name = "imported host memory '" + what + "'";
  const VkDeviceSize align = ctx.host_import_alignment();
  if (align == 0) return R::fail(name + ": " + ctx.info().name + " does not import host memory");
  if (bytes == 0 || p == nullptr) return R::fail(name + ": nothing to import");
  const std::uintptr_t first = reinterpret_cast<std::uintptr_t>(p) / align * align;
  const std::uintptr_t end = (reinterpret_cast<std::uintptr_t>(p) + bytes + align - 1) / align * align;
  const VkDeviceSize size = VkDeviceSize(end - first);
  if (size > ctx.max_allocation_bytes())
    return R::fail(name + ": " + std::to_string(size) + " bytes exceed maxMemoryAllocationSize " +
                   std::to_string(ctx.max_allocation_bytes()) + " bytes on " + ctx.info().name);
  void* host = reinterpret_cast<void*>(first);
  auto props_fn = reinterpret_cast<PFN_vkGetMemoryHostPointerPropertiesEXT>(
      vkGetDeviceProcAddr(ctx.device(), "vkGetMemoryHostPointerPropertiesEXT"));
  if (!props_fn) return R::fail(name + ": vkGetMemoryHostPointerPropertiesEXT missing on " + ctx.info().name);
  VkMemoryHostPointerPropertiesEXT hp{VK_STRUCTURE_TYPE_MEMORY_HOST_POINTER_PROPERTIES_EXT};
  VkResult r = props_fn(ctx.device(), VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT, host, &hp);
  if (r != VK_SUCCESS) return R::fail(name + ": the driver refuses the pointer: " + vk_result_name(r));
  GpuBuffer b;
  b.device_ = ctx.device();
  b.size_ = size;
  b.intent_ = MemoryIntent::DeviceLocal;
  VkExternalMemoryBufferCreateInfo ext{VK_STRUCTURE_TYPE_EXTERNAL_MEMORY_BUFFER_CREATE_INFO};
  ext.handleTypes = VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT;
  VkBufferCreateInfo bi{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  bi.pNext = &ext;
  bi.size = size;
  bi.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
             VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT;
  bi.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VK_CHECK(vkCreateBuffer(b.device_, &bi, nullptr, &b.buffer_));
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(b.device_, b.buffer_, &req);
  const auto type = find_memory(ctx.memory_properties(), req.memoryTypeBits & hp.memoryTypeBits, 0, 0, size);
  if (!type || req.size > size)
    return R::fail(name + ": no memory type for " + std::to_string(size) + " imported bytes on " + ctx.info().name);
  VkImportMemoryHostPointerInfoEXT imp{VK_STRUCTURE_TYPE_IMPORT_MEMORY_HOST_POINTER_INFO_EXT};
  imp.handleType = VK_EXTERNAL_MEMORY_HANDLE_TYPE_HOST_ALLOCATION_BIT_EXT;
  imp.pHostPointer = host;
  VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  ai.pNext = &imp;
  ai.allocationSize = size;
  ai.memoryTypeIndex = *type;
  r = vkAllocateMemory(b.device_, &ai, nullptr, &b.memory_);
  if (r != VK_SUCCESS) return R::fail(name + ": import of " + std::to_string(size) + " bytes failed: " + vk_result_name(r));
  VK_CHECK(vkBindBufferMemory(b.device_, b.buffer_, b.memory_, 0));
  offset = VkDeviceSize(reinterpret_cast<std::uintptr_t>(p) - first);
  return R::ok(std::move(b));
}

GpuBuffer& GpuBuffer::operator=(GpuBuffer&& o) noexcept {
  if (this != &o) {
    reset();
    device_ = o.device_;
    buffer_ = o.buffer_;
    memory_ = o.memory_;
    size_ = o.size_;
    intent_ = o.intent_;
    mapped_ = o.mapped_;
    o.buffer_ = VK_NULL_HANDLE;
    o.memory_ = VK_NULL_HANDLE;
    o.mapped_ = nullptr;
    o.size_ = 0;
  }
  return *this;
}

void GpuBuffer::reset() {
  // Buffer first, then its memory (the memory must outlive every buffer bound to it).
  if (buffer_) vkDestroyBuffer(device_, buffer_, nullptr);
  if (memory_) {
    if (mapped_) vkUnmapMemory(device_, memory_);
    count_free(memory_);
    vkFreeMemory(device_, memory_, nullptr);
  }
  buffer_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  mapped_ = nullptr;
  size_ = 0;
}

GpuBuffer make_buffer_or_throw(VulkanContext& ctx, VkDeviceSize bytes, MemoryIntent intent,
                               const std::string& what) {
  auto r = GpuBuffer::create(ctx, bytes, intent, what);
  if (!r) throw VulkanError(r.error);
  return std::move(*r.value);
}

void record_copy(VkCommandBuffer cmd, const GpuBuffer& src, const GpuBuffer& dst, VkDeviceSize bytes) {
  VkBufferCopy c{0, 0, bytes};
  vkCmdCopyBuffer(cmd, src.handle(), dst.handle(), 1, &c);
}

namespace {
void memory_barrier(VkCommandBuffer cmd, VkPipelineStageFlags src_stage, VkAccessFlags src_access,
                    VkPipelineStageFlags dst_stage, VkAccessFlags dst_access) {
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = src_access;
  mb.dstAccessMask = dst_access;
  vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 1, &mb, 0, nullptr, 0, nullptr);
}
}  // namespace

void barrier_compute_to_compute(VkCommandBuffer cmd) {
  memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_SHADER_READ_BIT,
                 VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                 VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_UNIFORM_READ_BIT);
}
void barrier_compute_to_indirect(VkCommandBuffer cmd) {
  memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                 VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                 VK_ACCESS_INDIRECT_COMMAND_READ_BIT | VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
}
void barrier_transfer_to_compute(VkCommandBuffer cmd) {
  memory_barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                 VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_UNIFORM_READ_BIT);
}
void barrier_compute_to_host(VkCommandBuffer cmd) {
  memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                 VK_ACCESS_HOST_READ_BIT);
}
void barrier_compute_to_transfer(VkCommandBuffer cmd) {
  memory_barrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                 VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
}
void barrier_transfer_to_host(VkCommandBuffer cmd) {
  memory_barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                 VK_ACCESS_HOST_READ_BIT);
}

DescriptorArena::DescriptorArena(VulkanContext& ctx, std::uint32_t max_sets, std::uint32_t max_buffers)
    : device_(ctx.device()) {
  // Any of the buffers may be a uniform buffer (ComputePipeline's uniform_bindings).
  const VkDescriptorPoolSize ps[3] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, std::max<std::uint32_t>(max_buffers, 1)},
                                      {VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, std::max<std::uint32_t>(max_buffers, 1)},
                                      {VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, std::max<std::uint32_t>(max_buffers, 1)}};
  VkDescriptorPoolCreateInfo pi{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  max_sets_ = std::max<std::uint32_t>(max_sets, 1);
  pi.maxSets = max_sets_;
  pi.poolSizeCount = 3;
  pi.pPoolSizes = ps;
  VK_CHECK(vkCreateDescriptorPool(device_, &pi, nullptr, &pool_));
}

DescriptorArena::~DescriptorArena() {
  for (VkBufferView v : views_) vkDestroyBufferView(device_, v, nullptr);
  if (pool_) vkDestroyDescriptorPool(device_, pool_, nullptr);
}

void DescriptorArena::reset() {
  VK_CHECK(vkResetDescriptorPool(device_, pool_, 0));
  for (VkBufferView v : views_) vkDestroyBufferView(device_, v, nullptr);
  views_.clear();
}

VkBufferView DescriptorArena::make_view(const BufferRange& r, VkFormat format) {
  VkBufferViewCreateInfo vi{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
  vi.buffer = r.buffer;
  vi.format = format;
  vi.offset = r.offset;
  vi.range = r.range;
  VkBufferView v = VK_NULL_HANDLE;
  VK_CHECK(vkCreateBufferView(device_, &vi, nullptr, &v));
  views_.push_back(v);
  return v;
}

VkDescriptorSet DescriptorArena::allocate(VkDescriptorSetLayout layout) {
  VkDescriptorSetAllocateInfo ai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  ai.descriptorPool = pool_;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &layout;
  VkDescriptorSet set;
  VK_CHECK(vkAllocateDescriptorSets(device_, &ai, &set));
  return set;
}

ComputePipelineBase::ComputePipelineBase(VulkanContext& ctx, const std::uint32_t* spirv,
                                         std::size_t spirv_bytes, std::uint32_t bindings,
                                         std::uint32_t push_bytes, std::string name,
                                         std::uint32_t uniform_bindings, std::vector<std::uint32_t> spec,
                                         std::uint32_t texel_bindings)
    : ctx_(ctx), name_(std::move(name)), bindings_(bindings), push_size_(push_bytes), uniform_(uniform_bindings),
      texel_(texel_bindings) {
  VkDevice dev = ctx_.device();
  std::vector<VkDescriptorSetLayoutBinding> b(bindings);
  for (std::uint32_t i = 0; i < bindings; ++i) {
    b[i].binding = i;
    b[i].descriptorType = descriptor_type(i);
    b[i].descriptorCount = 1;
    b[i].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
  }
  VkDescriptorSetLayoutCreateInfo dl{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  dl.bindingCount = bindings;
  dl.pBindings = b.data();
  VK_CHECK(vkCreateDescriptorSetLayout(dev, &dl, nullptr, &set_layout_));
  VkPushConstantRange pr{VK_SHADER_STAGE_COMPUTE_BIT, 0, push_bytes};
  VkPipelineLayoutCreateInfo pl{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  pl.setLayoutCount = 1;
  pl.pSetLayouts = &set_layout_;
  pl.pushConstantRangeCount = push_bytes ? 1 : 0;
  pl.pPushConstantRanges = &pr;
  VK_CHECK(vkCreatePipelineLayout(dev, &pl, nullptr, &layout_));
  VkShaderModuleCreateInfo sm{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  sm.codeSize = spirv_bytes;
  sm.pCode = spirv;
  VK_CHECK(vkCreateShaderModule(dev, &sm, nullptr, &module_));
  VkComputePipelineCreateInfo cp{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  cp.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
  cp.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  cp.stage.module = module_;
  cp.stage.pName = "main";
  std::vector<VkSpecializationMapEntry> entries(spec.size());
  for (std::uint32_t i = 0; i < spec.size(); ++i) entries[i] = {i, std::uint32_t(i * sizeof(std::uint32_t)), sizeof(std::uint32_t)};
  VkSpecializationInfo si{std::uint32_t(spec.size()), entries.data(), spec.size() * sizeof(std::uint32_t), spec.data()};
  if (!spec.empty()) cp.stage.pSpecializationInfo = &si;
  cp.layout = layout_;
  VK_CHECK(vkCreateComputePipelines(dev, VK_NULL_HANDLE, 1, &cp, nullptr, &pipeline_));
}

ComputePipelineBase::~ComputePipelineBase() {
  VkDevice dev = ctx_.device();
  if (pipeline_) vkDestroyPipeline(dev, pipeline_, nullptr);
  if (module_) vkDestroyShaderModule(dev, module_, nullptr);
  if (layout_) vkDestroyPipelineLayout(dev, layout_, nullptr);
  if (set_layout_) vkDestroyDescriptorSetLayout(dev, set_layout_, nullptr);
}

void ComputePipelineBase::bind_keeping_set(VkCommandBuffer cmd) const {
  vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_);
}

void ComputePipelineBase::bind(VkCommandBuffer cmd, DescriptorArena& arena,
                               std::initializer_list<BufferRange> buffers) const {
  if (buffers.size() != bindings_)
    throw std::logic_error(name_ + ": " + std::to_string(buffers.size()) + " buffers given for " +
                           std::to_string(bindings_) + " bindings");
  const VkDeviceSize limit = ctx_.max_binding_bytes();
  const auto& lim = ctx_.properties().limits;
  std::vector<VkDescriptorBufferInfo> info;
  std::vector<VkBufferView> views(bindings_, VK_NULL_HANDLE);
  std::uint32_t at = 0;
  for (const BufferRange& r : buffers) {
    if ((texel_ >> at) & 1u) {
      const bool u4 = (texel_uint4_ >> at) & 1u, v4 = u4 || ((texel_vec4_ >> at) & 1u);
      const VkDeviceSize texel = v4 ? 16 : 4;
      if (r.range / texel > lim.maxTexelBufferElements || r.offset % lim.minTexelBufferOffsetAlignment != 0 ||
          r.range % texel != 0)
        throw std::logic_error(name_ + ": texel binding of " + std::to_string(r.range) + " bytes at offset " +
                               std::to_string(r.offset) + " exceeds maxTexelBufferElements " +
                               std::to_string(lim.maxTexelBufferElements) + ", misses the alignment " +
                               std::to_string(lim.minTexelBufferOffsetAlignment) + " or is no whole number of " +
                               std::to_string(texel) + "-byte texels");
      views[at] = arena.make_view(r, u4 ? VK_FORMAT_R32G32B32A32_UINT
                                     : v4 ? VK_FORMAT_R32G32B32A32_SFLOAT : VK_FORMAT_R32_SFLOAT);
    } else if (r.range > limit) {
      throw std::logic_error(name_ + ": binding of " + std::to_string(r.range) +
                             " bytes exceeds maxStorageBufferRange " + std::to_string(limit));
    }
    info.push_back({r.buffer, r.offset, r.range});
    ++at;
  }
  VkDescriptorSet set = arena.allocate(set_layout_);
  std::vector<VkWriteDescriptorSet> w(bindings_);
  for (std::uint32_t i = 0; i < bindings_; ++i) {
    w[i] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    w[i].dstSet = set;
    w[i].dstBinding = i;
    w[i].descriptorCount = 1;
    w[i].descriptorType = descriptor_type(i);
    if ((texel_ >> i) & 1u)
      w[i].pTexelBufferView = &views[i];
    else
      w[i].pBufferInfo = &info[i];
  }
  vkUpdateDescriptorSets(ctx_.device(), bindings_, w.data(), 0, nullptr);
  vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_);
  vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout_, 0, 1, &set, 0, nullptr);
}

void ComputePipelineBase::push_bytes(VkCommandBuffer cmd, const void* data) const {
  vkCmdPushConstants(cmd, layout_, VK_SHADER_STAGE_COMPUTE_BIT, 0, push_size_, data);
}

GpuTimer::GpuTimer(VulkanContext& ctx, std::uint32_t max_marks) : ctx_(ctx), count_(max_marks) {
  if (!ctx_.timestamps_supported() || max_marks == 0) return;
  VkQueryPoolCreateInfo qi{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
  qi.queryType = VK_QUERY_TYPE_TIMESTAMP;
  qi.queryCount = max_marks;
  VK_CHECK(vkCreateQueryPool(ctx_.device(), &qi, nullptr, &pool_));
}

GpuTimer::~GpuTimer() {
  if (pool_) vkDestroyQueryPool(ctx_.device(), pool_, nullptr);
}

void GpuTimer::record_reset(VkCommandBuffer cmd) {
  if (pool_) vkCmdResetQueryPool(cmd, pool_, 0, count_);
}

void GpuTimer::mark(VkCommandBuffer cmd, std::uint32_t i) {
  if (pool_ && i < count_)
    vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, pool_, i);
}

double GpuTimer::elapsed_ms(std::uint32_t a, std::uint32_t b) const {
  if (!pool_ || a >= count_ || b >= count_) return -1;
  std::uint64_t ta = 0, tb = 0;
  const VkQueryResultFlags f = VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT;
  if (vkGetQueryPoolResults(ctx_.device(), pool_, a, 1, sizeof(ta), &ta, sizeof(ta), f) != VK_SUCCESS ||
      vkGetQueryPoolResults(ctx_.device(), pool_, b, 1, sizeof(tb), &tb, sizeof(tb), f) != VK_SUCCESS ||
      tb < ta)
    return -1;
  return double(tb - ta) * double(ctx_.properties().limits.timestampPeriod) * 1e-6;
}

bool slabs_hold_quads(int nx, const std::vector<Slab>& slabs) {
  if (nx % 4 != 0) return false;
  for (const Slab& s : slabs)
    if (s.src_offset_elems % 4 != 0 || s.src.offset % 16 != 0 || s.src.range % 16 != 0) return false;
  return true;
}

Result<std::vector<Slab>> plan_slabs(const VulkanContext& ctx, const SlabGeometry& g, VkBuffer src,
                                     VkBuffer dst, std::uint64_t limit, const std::string& what) {
  using R = Result<std::vector<Slab>>;
  const auto& lim = ctx.properties().limits;
  // Bindings may be storage buffers or texel-buffer views: both alignments hold.
  const std::uint64_t align = std::max<std::uint64_t>(
      {lim.minStorageBufferOffsetAlignment, lim.minTexelBufferOffsetAlignment, 4});
  const std::uint64_t m = std::max<std::uint64_t>(g.z_multiple, 1);
  auto src_range = [&](std::uint64_t z0, std::uint64_t nz) {
    const std::uint64_t a = z0 > g.halo ? z0 - g.halo : 0;
    const std::uint64_t b = std::min(g.nz, z0 + nz + g.halo);
    return std::pair{a, b};
  };
  auto fits = [&](std::uint64_t z0, std::uint64_t nz) {
    const auto [a, b] = src_range(z0, nz);
    const std::uint64_t s = (b - a) * g.src_bytes_per_slice + align;
    const std::uint64_t d = g.dst_bytes_before(std::min(g.nz, nz), g.user) + align;  // dst: uniform in z
    return s <= limit && d <= limit;
  };
  // Largest slab (a multiple of m slices) that fits at the worst place (the interior,
  // where the halo is on both sides); the dispatch count limits it too.
  std::uint64_t slab = (g.nz + m - 1) / m * m;
  const std::uint64_t max_units = std::uint64_t(lim.maxComputeWorkGroupCount[2]) * g.wg_z;
  slab = std::min(slab, max_units * m);
  while (slab > 0 && !fits(std::min<std::uint64_t>(g.halo, g.nz), slab)) slab -= m;
  if (slab == 0)
    return R::fail(what + ": a slab of " + std::to_string(m) + " slice(s) of " +
                   std::to_string(g.src_bytes_per_slice) + " bytes (plus " + std::to_string(g.halo) +
                   " halo slice(s) each side) does not fit a storage-buffer binding of " +
                   std::to_string(limit) + " bytes on " + ctx.info().name);
  std::vector<Slab> out;
  for (std::uint64_t z0 = 0; z0 < g.nz; z0 += slab) {
    Slab s;
    s.z0 = z0;
    s.nz = std::min(slab, g.nz - z0);
    std::tie(s.src_z0, s.src_z1) = src_range(z0, s.nz);
    const std::uint64_t sb = s.src_z0 * g.src_bytes_per_slice, se = s.src_z1 * g.src_bytes_per_slice;
    const std::uint64_t db = g.dst_bytes_before(z0, g.user), de = g.dst_bytes_before(z0 + s.nz, g.user);
    const std::uint64_t sbind = sb / align * align, dbind = db / align * align;
    s.src = {src, sbind, se - sbind};
    s.dst = {dst, dbind, de - dbind};
    s.src_offset_elems = (sb - sbind) / g.src_elem_bytes;
    s.dst_offset_elems = (db - dbind) / g.dst_elem_bytes;
    out.push_back(s);
  }
  return R::ok(std::move(out));
}

}  // namespace isotouch::engine
