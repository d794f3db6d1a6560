#include "gradient_pass.h"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstring>

#include "cpu_gradient.h"
#include "isotouch/shaders/gradient_spv.h"
#include "isotouch_shared.h"

namespace isotouch::engine {

// Pin the C++ view of the shared structs to the GLSL (std430 / push-constant) layout.
using gpu::GradientPush;
static_assert(sizeof(GradientPush) == 64, "GradientPush must be 16 4-byte members");
static_assert(offsetof(GradientPush, nx) == 0);
static_assert(offsetof(GradientPush, slab_nz) == 16);
static_assert(offsetof(GradientPush, dst_offset) == 28);
static_assert(offsetof(GradientPush, inv_2h_x) == 32);
static_assert(offsetof(GradientPush, inv_h_x) == 44);
static_assert(offsetof(GradientPush, inv_h_z) == 52);
static_assert(sizeof(servo::Sample) == 16 && offsetof(servo::Sample, value) == 0 &&
                  offsetof(servo::Sample, gx) == 4 && offsetof(servo::Sample, gz) == 12,
              "servo::Sample must match the vec4 written by gradient.comp");

namespace {
std::uint32_t group_count(std::uint64_t n, std::uint32_t wg) {
  return std::uint32_t((n + wg - 1) / wg);  // round up; the shader guards the tail
}
}  // namespace

GradientPass::GradientPass(VulkanContext& ctx) : ctx_(ctx) {
  VkDevice dev = ctx_.device();
  VkDescriptorSetLayoutBinding b[2] = {};
  for (std::uint32_t i = 0; i < 2; ++i) {
    b[i].binding = i;
    b[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    b[i].descriptorCount = 1;
    b[i].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
  }
  VkDescriptorSetLayoutCreateInfo dl{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  dl.bindingCount = 2;
  dl.pBindings = b;
  VK_CHECK(vkCreateDescriptorSetLayout(dev, &dl, nullptr, &set_layout_));
  VkPushConstantRange pr{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(GradientPush)};
  VkPipelineLayoutCreateInfo pl{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  pl.setLayoutCount = 1;
  pl.pSetLayouts = &set_layout_;
  pl.pushConstantRangeCount = 1;
  pl.pPushConstantRanges = &pr;
  VK_CHECK(vkCreatePipelineLayout(dev, &pl, nullptr, &layout_));
  VkShaderModuleCreateInfo sm{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  sm.codeSize = sizeof(gradient_spv);
  sm.pCode = gradient_spv;
  VK_CHECK(vkCreateShaderModule(dev, &sm, nullptr, &module_));
  VkComputePipelineCreateInfo cp{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  cp.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
  cp.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  cp.stage.module = module_;
  cp.stage.pName = "main";
  cp.layout = layout_;
  VK_CHECK(vkCreateComputePipelines(dev, VK_NULL_HANDLE, 1, &cp, nullptr, &pipeline_));
}

GradientPass::~GradientPass() {
  VkDevice dev = ctx_.device();
  vkDestroyPipeline(dev, pipeline_, nullptr);
  vkDestroyShaderModule(dev, module_, nullptr);
  vkDestroyPipelineLayout(dev, layout_, nullptr);
  vkDestroyDescriptorSetLayout(dev, set_layout_, nullptr);
}

servo::SampleField GradientPass::run(const Volume& vol, GradientTimings* timings,
                                     std::uint64_t max_binding_bytes) {
  using clock = std::chrono::steady_clock;
  GradientTimings t;
  const auto [nx, ny, nz] = vol.grid.dims;
  const std::uint64_t slice = std::uint64_t(nx) * std::uint64_t(ny);
  const auto& lim = ctx_.properties().limits;
  std::uint64_t limit = lim.maxStorageBufferRange;
  if (max_binding_bytes) limit = std::min<std::uint64_t>(limit, max_binding_bytes);
  const std::uint64_t align = std::max<std::uint64_t>(lim.minStorageBufferOffsetAlignment, 4);

  // Slices per slab: dst needs slab_nz * slice * 16 bytes, src (slab_nz + 2) * slice * 4,
  // each plus up to `align` bytes of slack from rounding the binding offset down.
  std::uint64_t slab_nz = limit > align ? (limit - align) / (slice * 16) : 0;
  while (slab_nz > 0 && (slab_nz + 2) * slice * 4 + align > limit) --slab_nz;
  slab_nz = std::min<std::uint64_t>(slab_nz, std::uint64_t(nz));
  slab_nz = std::min<std::uint64_t>(slab_nz, std::uint64_t(lim.maxComputeWorkGroupCount[2]) *
                                                 ISOTOUCH_GRADIENT_WG_Z);
  if (slab_nz == 0)
    throw VolumeError(vol.path + ": one z-slice of " + std::to_string(nx) + " x " +
                      std::to_string(ny) + " samples does not fit a storage-buffer binding of " +
                      std::to_string(limit) + " bytes on " + ctx_.info().name);
  if (group_count(std::uint64_t(nx), ISOTOUCH_GRADIENT_WG_X) > lim.maxComputeWorkGroupCount[0] ||
      group_count(std::uint64_t(ny), ISOTOUCH_GRADIENT_WG_Y) > lim.maxComputeWorkGroupCount[1])
    throw VolumeError(vol.path + ": volume too wide for one dispatch on " + ctx_.info().name);
  const std::uint32_t slabs = std::uint32_t((std::uint64_t(nz) + slab_nz - 1) / slab_nz);
  t.slabs = int(slabs);

  const std::uint64_t n = vol.grid.voxel_count();
  Buffer src = ctx_.create_buffer(n * sizeof(float), false);
  Buffer dst = ctx_.create_buffer(n * sizeof(servo::Sample), true);
  VkDescriptorPool pool = VK_NULL_HANDLE;
  VkQueryPool queries = VK_NULL_HANDLE;
  // Released on every path out of here, exceptions included.
  struct Release {
    VulkanContext& ctx;
    Buffer& src;
    Buffer& dst;
    VkDescriptorPool& pool;
    VkQueryPool& queries;
    ~Release() {
      if (queries) vkDestroyQueryPool(ctx.device(), queries, nullptr);
      if (pool) vkDestroyDescriptorPool(ctx.device(), pool, nullptr);
      ctx.destroy_buffer(src);
      ctx.destroy_buffer(dst);
    }
  } release{ctx_, src, dst, pool, queries};
  servo::SampleField out;
  {
    auto t0 = clock::now();
    std::memcpy(src.mapped, vol.voxels.data(), n * sizeof(float));
    t.upload_ms = std::chrono::duration<double, std::milli>(clock::now() - t0).count();

    VkDescriptorPoolSize ps{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 2 * slabs};
    VkDescriptorPoolCreateInfo pi{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    pi.maxSets = slabs;
    pi.poolSizeCount = 1;
    pi.pPoolSizes = &ps;
    VK_CHECK(vkCreateDescriptorPool(ctx_.device(), &pi, nullptr, &pool));
    if (ctx_.timestamps_supported()) {
      VkQueryPoolCreateInfo qi{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
      qi.queryType = VK_QUERY_TYPE_TIMESTAMP;
      qi.queryCount = 2;
      VK_CHECK(vkCreateQueryPool(ctx_.device(), &qi, nullptr, &queries));
    }

    const GradientConstants k = gradient_constants(vol.grid);
    VkCommandBuffer cmd = ctx_.begin_commands();
    if (queries) {
      vkCmdResetQueryPool(cmd, queries, 0, 2);
      vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries, 0);
    }
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_);
    for (std::uint32_t s = 0; s < slabs; ++s) {
      const std::uint64_t z0 = s * slab_nz;
      const std::uint64_t snz = std::min<std::uint64_t>(slab_nz, std::uint64_t(nz) - z0);
      const std::uint64_t src_z0 = z0 > 0 ? z0 - 1 : 0;
      const std::uint64_t src_z1 = std::min<std::uint64_t>(std::uint64_t(nz), z0 + snz + 1);
      const std::uint64_t src_byte = src_z0 * slice * 4, dst_byte = z0 * slice * 16;
      const std::uint64_t src_bind = src_byte / align * align, dst_bind = dst_byte / align * align;

      VkDescriptorSetAllocateInfo ai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
      ai.descriptorPool = pool;
      ai.descriptorSetCount = 1;
      ai.pSetLayouts = &set_layout_;
      VkDescriptorSet set;
      VK_CHECK(vkAllocateDescriptorSets(ctx_.device(), &ai, &set));
      VkDescriptorBufferInfo bi[2] = {
          {src.buffer, src_bind, src_z1 * slice * 4 - src_bind},
          {dst.buffer, dst_bind, (z0 + snz) * slice * 16 - dst_bind}};
      VkWriteDescriptorSet w[2] = {};
      for (std::uint32_t i = 0; i < 2; ++i) {
        w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
        w[i].dstSet = set;
        w[i].dstBinding = i;
        w[i].descriptorCount = 1;
        w[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
        w[i].pBufferInfo = &bi[i];
      }
      vkUpdateDescriptorSets(ctx_.device(), 2, w, 0, nullptr);
      vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout_, 0, 1, &set, 0, nullptr);

      GradientPush pc{};
      pc.nx = gpu::uint(nx);
      pc.ny = gpu::uint(ny);
      pc.nz = gpu::uint(nz);
      pc.z0 = gpu::uint(z0);
      pc.slab_nz = gpu::uint(snz);
      pc.src_z0 = gpu::uint(src_z0);
      pc.src_offset = gpu::uint((src_byte - src_bind) / 4);
      pc.dst_offset = gpu::uint((dst_byte - dst_bind) / 16);
      pc.inv_2h_x = k.inv_2h[0];
      pc.inv_2h_y = k.inv_2h[1];
      pc.inv_2h_z = k.inv_2h[2];
      pc.inv_h_x = k.inv_h[0];
      pc.inv_h_y = k.inv_h[1];
      pc.inv_h_z = k.inv_h[2];
      vkCmdPushConstants(cmd, layout_, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc), &pc);
      vkCmdDispatch(cmd, group_count(std::uint64_t(nx), ISOTOUCH_GRADIENT_WG_X),
                    group_count(std::uint64_t(ny), ISOTOUCH_GRADIENT_WG_Y),
                    group_count(snz, ISOTOUCH_GRADIENT_WG_Z));
    }
    if (queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, queries, 1);
    VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
    mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT,
                         0, 1, &mb, 0, nullptr, 0, nullptr);
    t.submit_wall_ms = ctx_.submit_and_wait(cmd);
    t.gradient_ms = t.submit_wall_ms;
    if (queries) {
      std::uint64_t ts[2] = {0, 0};
      if (vkGetQueryPoolResults(ctx_.device(), queries, 0, 2, sizeof(ts), ts, sizeof(std::uint64_t),
                                VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT) == VK_SUCCESS &&
          ts[1] >= ts[0]) {
        t.gradient_ms = double(ts[1] - ts[0]) * double(ctx_.properties().limits.timestampPeriod) * 1e-6;
        t.gpu_timestamps = true;
      }
    }

    t0 = clock::now();
    out.grid = vol.grid;
    out.samples.resize(n);
    std::memcpy(out.samples.data(), dst.mapped, n * sizeof(servo::Sample));
    t.download_ms = std::chrono::duration<double, std::milli>(clock::now() - t0).count();
  }
  if (timings) *timings = t;
  return out;
}

}  // namespace isotouch::engine
