#include "isotouch/engine/gradient_pass.h"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstring>

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/shaders/gradient_spv.h"
#include "isotouch/shaders/copy_x4_spv.h"
#include "isotouch/shaders/gradient_whole_x4_spv.h"
#include "isotouch/shaders/gradient_x4_spv.h"
#include "isotouch/shaders/isotouch_shared.h"

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
static_assert(sizeof(core::Sample) == 16 && offsetof(core::Sample, value) == 0 &&
                  offsetof(core::Sample, gx) == 4 && offsetof(core::Sample, gz) == 12,
              "core::Sample must match the vec4 written by gradient.comp");

namespace {
std::uint32_t group_count(std::uint64_t n, std::uint32_t wg) {
  return std::uint32_t((n + wg - 1) / wg);  // round up; the shader guards the tail
}
std::uint64_t samples_before(std::uint64_t z, const void* user) {
  return z * *static_cast<const std::uint64_t*>(user);
}
}  // namespace

static_assert(sizeof(gpu::DensePush) == 64, "DensePush must be 16 4-byte members");
static_assert(offsetof(gpu::DensePush, qx) == 32 && offsetof(gpu::DensePush, inv_2h_x) == 40 &&
              offsetof(gpu::DensePush, inv_h_z) == 60);

const char* shader_set_name(ShaderSet s) { return s == ShaderSet::Legacy ? "legacy" : "current"; }

GradientPass::GradientPass(VulkanContext& ctx, ShaderSet shaders) : ctx_(ctx), shaders_(shaders) {
  if (shaders == ShaderSet::Legacy)
    legacy_ = std::make_unique<ComputePipeline<GradientPush>>(ctx, gradient_spv, 2, "gradient");
}

GradientPass::~GradientPass() = default;

std::vector<Slab> GradientPass::plan(const core::Grid& grid, VkBuffer src, VkBuffer dst,
                                     std::uint64_t max_binding_bytes, const std::string& what) const {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const auto& lim = ctx_.properties().limits;
  std::uint64_t limit = lim.maxStorageBufferRange;
  if (max_binding_bytes) limit = std::min<std::uint64_t>(limit, max_binding_bytes);
  const bool x4 = shaders_ == ShaderSet::Current;
  const std::uint64_t rows = (std::uint64_t(nx) + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS * std::uint64_t(ny);
  if (x4 ? group_count(rows, ISOTOUCH_DENSE_WG) > lim.maxComputeWorkGroupCount[0]
         : (group_count(std::uint64_t(nx), ISOTOUCH_GRADIENT_WG_X) > lim.maxComputeWorkGroupCount[0] ||
            group_count(std::uint64_t(ny), ISOTOUCH_GRADIENT_WG_Y) > lim.maxComputeWorkGroupCount[1]))
    throw VolumeError(what + ": volume too wide for one dispatch on " + ctx_.info().name);
  const std::uint64_t slice = std::uint64_t(nx) * std::uint64_t(ny);
  const std::uint64_t dst_slice_bytes = slice * sizeof(core::Sample);
  SlabGeometry g;
  g.nz = std::uint64_t(nz);
  g.src_bytes_per_slice = slice * 4;
  g.src_elem_bytes = 4;
  g.halo = 1;
  g.dst_bytes_before = &samples_before;
  g.user = &dst_slice_bytes;
  g.dst_elem_bytes = sizeof(core::Sample);
  g.wg_z = x4 ? 1 : ISOTOUCH_GRADIENT_WG_Z;
  auto slabs = plan_slabs(ctx_, g, src, dst, limit, what + ": gradient");
  if (!slabs) throw VolumeError(slabs.error);
  return std::move(*slabs.value);
}

bool GradientPass::whole_field(const core::Grid& grid, const std::vector<Slab>& slabs) const {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const auto& lim = ctx_.properties().limits;
  return shaders_ == ShaderSet::Current && slabs.size() == 1 && slabs_hold_quads(nx, slabs) && nx >= 8 && ny >= 2 &&
         nz >= 2 && slabs[0].src_offset_elems == 0 && slabs[0].dst_offset_elems == 0 &&
         grid.voxel_count() <= lim.maxTexelBufferElements &&
         group_count(std::uint64_t(nx) / ISOTOUCH_DENSE_VOXELS, ISOTOUCH_DENSE_WG) <= lim.maxComputeWorkGroupCount[0] &&
         std::uint64_t(ny) <= lim.maxComputeWorkGroupCount[1] && std::uint64_t(nz) <= lim.maxComputeWorkGroupCount[2];
}

void GradientPass::record_whole(VkCommandBuffer cmd, DescriptorArena& arena, const core::Grid& grid,
                                const Slab& s) const {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const GradientConstants k = gradient_constants(grid);
  auto bits = [](float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
  };
  const std::vector<std::uint32_t> spec = {std::uint32_t(nx),  std::uint32_t(ny),  std::uint32_t(nz),
                                           bits(k.inv_2h[0]), bits(k.inv_2h[1]), bits(k.inv_2h[2]),
                                           bits(k.inv_h[0]),  bits(k.inv_h[1]),  bits(k.inv_h[2])};
  if (!whole_ || spec != whole_spec_) {
    whole_ = std::make_unique<ComputePipeline<gpu::DensePush>>(ctx_, gradient_whole_x4_spv, 3, "gradient_whole_x4", 0u,
                                                               spec, 0b101u);
    whole_->set_texel_vec4(1u);
    whole_spec_ = spec;
  }
  whole_->bind(cmd, arena, {s.src, s.dst, s.src});  // the field as quads, the samples, the field as floats
  vkCmdDispatch(cmd, group_count(std::uint64_t(nx) / ISOTOUCH_DENSE_VOXELS, ISOTOUCH_DENSE_WG), std::uint32_t(ny),
                std::uint32_t(nz));
}

void GradientPass::record(VkCommandBuffer cmd, DescriptorArena& arena, const core::Grid& grid,
                          const std::vector<Slab>& slabs) const {
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const GradientConstants k = gradient_constants(grid);
  if (whole_field(grid, slabs)) {
    record_whole(cmd, arena, grid, slabs[0]);
    return;
  }
  if (shaders_ == ShaderSet::Current) {
    const bool quads = slabs_hold_quads(nx, slabs);
    auto& pipe = x4_[{nx, ny, nz, quads ? 1 : 0}];
    if (!pipe) {
      pipe = std::make_unique<ComputePipeline<gpu::DensePush>>(
          ctx_, gradient_x4_spv, 2, "gradient_x4", 0u,
          std::vector<std::uint32_t>{std::uint32_t(nx), std::uint32_t(ny), std::uint32_t(nz), quads ? 1u : 0u}, 1u);
      if (quads) pipe->set_texel_vec4(1u);
    }
    const std::uint32_t qx = std::uint32_t((nx + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS);
    for (const Slab& s : slabs) {
      pipe->bind(cmd, arena, {s.src, s.dst});
      gpu::DensePush pc{};
      pc.nx = gpu::uint(nx);
      pc.ny = gpu::uint(ny);
      pc.nz = gpu::uint(nz);
      pc.z0 = gpu::uint(s.z0);
      pc.slab_nz = gpu::uint(s.nz);
      pc.src_z0 = gpu::uint(s.src_z0);
      pc.src_offset = gpu::uint(s.src_offset_elems);
      pc.dst_offset = gpu::uint(s.dst_offset_elems);
      pc.qx = qx;
      set_inverse_spacings(pc, k);
      pipe->push(cmd, pc);
      vkCmdDispatch(cmd, group_count(std::uint64_t(qx) * std::uint64_t(ny), ISOTOUCH_DENSE_WG), 1,
                    std::uint32_t(s.nz));
    }
    return;
  }
  for (const Slab& s : slabs) {
    legacy_->bind(cmd, arena, {s.src, s.dst});
    GradientPush pc{};
    pc.nx = gpu::uint(nx);
    pc.ny = gpu::uint(ny);
    pc.nz = gpu::uint(nz);
    pc.z0 = gpu::uint(s.z0);
    pc.slab_nz = gpu::uint(s.nz);
    pc.src_z0 = gpu::uint(s.src_z0);
    pc.src_offset = gpu::uint(s.src_offset_elems);
    pc.dst_offset = gpu::uint(s.dst_offset_elems);
    set_inverse_spacings(pc, k);
    legacy_->push(cmd, pc);
    vkCmdDispatch(cmd, group_count(std::uint64_t(nx), ISOTOUCH_GRADIENT_WG_X),
                  group_count(std::uint64_t(ny), ISOTOUCH_GRADIENT_WG_Y),
                  group_count(s.nz, ISOTOUCH_GRADIENT_WG_Z));
  }
}

double GradientPass::copy_floor_ms(const Volume& vol, int runs, FloorTraffic traffic) {
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  const std::uint64_t n = vol.grid.voxel_count();
  auto buffer = [&](std::uint64_t bytes, const char* what) {
    auto r = GpuBuffer::create(ctx_, bytes, MemoryIntent::DeviceLocal, what);
    if (!r) throw VolumeError(vol.path + ": " + r.error);
    return std::move(*r.value);
  };
  GpuBuffer src = buffer(n * sizeof(float), "voxels (copy floor)");
  GpuBuffer dst = buffer(n * sizeof(core::Sample), "samples (copy floor)");
  GradientPass planner(ctx_, ShaderSet::Current);
  const std::vector<Slab> slabs = planner.plan(vol.grid, src.handle(), dst.handle(), 0, vol.path);
  const bool quads = slabs_hold_quads(nx, slabs);  // the gradient's own input form
  ComputePipeline<gpu::DensePush> pipe(
      ctx_, copy_x4_spv, 2, "copy_x4", 0u,
      std::vector<std::uint32_t>{std::uint32_t(nx), std::uint32_t(ny), std::uint32_t(nz), quads ? 1u : 0u,
                                 std::uint32_t(traffic)},
      1u);
  if (quads) pipe.set_texel_vec4(1u);
  const std::uint32_t qx = std::uint32_t((nx + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS);
  std::vector<double> ms;
  for (int r = 0; r <= runs; ++r) {
    DescriptorArena arena(ctx_, std::uint32_t(slabs.size()), 2 * std::uint32_t(slabs.size()));
    GpuTimer timer(ctx_, 2);
    VkCommandBuffer cmd = ctx_.begin_commands();
    timer.record_reset(cmd);
    timer.mark(cmd, 0);
    for (const Slab& s : slabs) {
      pipe.bind(cmd, arena, {s.src, s.dst});
      gpu::DensePush pc{};
      pc.nx = gpu::uint(nx);
      pc.ny = gpu::uint(ny);
      pc.nz = gpu::uint(nz);
      pc.z0 = gpu::uint(s.z0);
      pc.slab_nz = gpu::uint(s.nz);
      pc.src_z0 = gpu::uint(s.src_z0);
      pc.src_offset = gpu::uint(s.src_offset_elems);
      pc.dst_offset = gpu::uint(s.dst_offset_elems);
      pc.qx = qx;
      pipe.push(cmd, pc);
      vkCmdDispatch(cmd, group_count(std::uint64_t(qx) * std::uint64_t(ny), ISOTOUCH_DENSE_WG), 1, std::uint32_t(s.nz));
    }
    timer.mark(cmd, 1);
    const double wall = ctx_.submit_and_wait(cmd);
    const double dev = timer.elapsed_ms(0, 1);
    if (r > 0) ms.push_back(dev >= 0 ? dev : wall);  // run 0: first touch of the buffers, untimed
  }
  std::sort(ms.begin(), ms.end());
  return ms.empty() ? -1.0 : ms[ms.size() / 2];
}

core::SampleField GradientPass::run(const Volume& vol, GradientTimings* timings,
                                     std::uint64_t max_binding_bytes) {
  using clock = std::chrono::steady_clock;
  GradientTimings t;
  const std::uint64_t n = vol.grid.voxel_count();
  auto buffer = [&](std::uint64_t bytes, MemoryIntent intent, const char* what) {
    auto r = GpuBuffer::create(ctx_, bytes, intent, what);
    if (!r) throw VolumeError(vol.path + ": " + r.error);
    return std::move(*r.value);
  };
  GpuBuffer src = buffer(n * sizeof(float), MemoryIntent::DeviceLocal, "voxels");
  GpuBuffer dst = buffer(n * sizeof(core::Sample), MemoryIntent::DeviceLocal, "samples");
  const std::vector<Slab> slabs = plan(vol.grid, src.handle(), dst.handle(), max_binding_bytes, vol.path);
  t.slabs = int(slabs.size());
  const bool direct = src.mapped() && dst.mapped();  // zero copy: host-visible device memory
  GpuBuffer up, down;
  if (!direct) {
    up = buffer(n * sizeof(float), MemoryIntent::Upload, "voxels staging");
    down = buffer(n * sizeof(core::Sample), MemoryIntent::Readback, "samples readback");
  }
  DescriptorArena arena(ctx_, std::uint32_t(slabs.size()), 3 * std::uint32_t(slabs.size()));
  GpuTimer timer(ctx_, 2);

  auto t0 = clock::now();
  std::memcpy(direct ? src.mapped() : up.mapped(), vol.voxels.data(), n * sizeof(float));
  t.upload_ms = std::chrono::duration<double, std::milli>(clock::now() - t0).count();

  VkCommandBuffer cmd = ctx_.begin_commands();
  timer.record_reset(cmd);
  if (!direct) {
    record_copy(cmd, up, src, n * sizeof(float));
    barrier_transfer_to_compute(cmd);
  }
  timer.mark(cmd, 0);
  record(cmd, arena, vol.grid, slabs);
  timer.mark(cmd, 1);
  if (direct) {
    barrier_compute_to_host(cmd);
  } else {
    barrier_compute_to_transfer(cmd);
    record_copy(cmd, dst, down, n * sizeof(core::Sample));
    barrier_transfer_to_host(cmd);
  }
  t.submit_wall_ms = ctx_.submit_and_wait(cmd);
  t.gradient_ms = t.submit_wall_ms;
  if (const double ms = timer.elapsed_ms(0, 1); ms >= 0) {
    t.gradient_ms = ms;
    t.gpu_timestamps = true;
  }

  core::SampleField out;
  t0 = clock::now();
  out.grid = vol.grid;
  out.samples.resize(n);
  std::memcpy(out.samples.data(), direct ? dst.mapped() : down.mapped(), n * sizeof(core::Sample));
  t.download_ms = std::chrono::duration<double, std::milli>(clock::now() - t0).count();
  if (timings) *timings = t;
  return out;
}

}  // namespace isotouch::engine
