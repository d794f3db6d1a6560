// brush.cpp - the GPU brush engine (shaders/brush.comp, brush.h), in isotouch::session_gpu.
//
// One application = one command buffer: (smooth only) copy of the pre-edit slices the
// brush reads into a scratch buffer; the dirty flags zeroed; one box dispatch per z-chunk of
// brick layers (one 8x8x8 workgroup per touched brick; each chunk binds a window of whole
// slices that fits a storage binding); the flags and (with a host mirror) the box of
// touched voxels copied to readback buffers. The host then reads the dirty flags and copies
// the dirty bricks into the mirror.
#include "isotouch/session/brush.h"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <utility>

#include "isotouch/core/brick_field.h"
#include "isotouch/shaders/brush_spv.h"
#include "isotouch/engine/vk_resources.h"

namespace isotouch::session {
using engine::make_buffer_or_throw;
using engine::record_copy;
using engine::BufferRange;
using engine::ComputePipeline;
using engine::DescriptorArena;
using engine::GpuBuffer;
using engine::GpuTimer;
using engine::MemoryIntent;
using engine::Result;
using engine::Volume;
using engine::VolumeError;
using engine::VulkanContext;
using engine::barrier_transfer_to_compute;
using engine::barrier_compute_to_compute;
using engine::barrier_compute_to_transfer;
using engine::barrier_transfer_to_host;

static_assert(sizeof(gpu::BrushPush) == 124, "BrushPush: 31 4-byte members (std430)");
static_assert(sizeof(gpu::BrushPush) <= 128, "within the guaranteed push-constant size");
static_assert(offsetof(gpu::BrushPush, cx) == 48 && offsetof(gpu::BrushPush, inv_dens_scale) == 96,
              "BrushPush offsets shared with shaders/brush.comp");
static_assert(ISOTOUCH_BRUSH_WG == ISOTOUCH_BRICK && ISOTOUCH_BRICK == unsigned(core::kBrickSize),
              "one workgroup per 8^3 brick");

namespace {
double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

struct BrushEngine::Impl {
  VulkanContext& ctx;
  core::Grid grid;
  std::string path;
  ComputePipeline<gpu::BrushPush> pipe;
  GpuBuffer vol;                            ///< the resident raw volume (device-local)
  GpuBuffer scratch, flags, flags_down, box_down, upload;  ///< grown on demand
  std::uint64_t limit = 0;                  ///< binding limit [bytes]
  std::uint64_t align = 4;                  ///< minStorageBufferOffsetAlignment
  /// Kept between applications (an edit is latency-bound: no pool or query-pool creation
  /// per brush); the descriptor arena grows when a brush needs more z-chunks.
  std::unique_ptr<DescriptorArena> arena;
  GpuTimer timer;
  std::string type;                         ///< the device's type (DeviceInfo::type)
  Impl(VulkanContext& c, const Volume& v)
      : ctx(c), grid(v.grid), path(v.path), pipe(c, brush_spv, 3, "brush"), timer(c, 2), type(c.info().type) {}
  /// The arena, reset, with room for `sets` descriptor sets of 3 buffers.
  DescriptorArena& arena_for(std::uint32_t sets) {
    if (!arena || arena->max_sets() < sets) arena = std::make_unique<DescriptorArena>(ctx, sets, 3 * sets);
    else arena->reset();
    return *arena;
  }

  std::uint64_t slice_bytes() const { return std::uint64_t(grid.dims[0]) * std::uint64_t(grid.dims[1]) * 4; }
  /// (Re)allocates `b` if it is smaller than `bytes`.
  void ensure(GpuBuffer& b, std::uint64_t bytes, MemoryIntent intent, const char* what) {
    bytes = std::max<std::uint64_t>(bytes, 16);
    if (b && b.size() >= bytes) return;
    b.reset();
    auto r = GpuBuffer::create(ctx, bytes, intent, what);
    if (!r) throw VolumeError(path + ": brush engine: " + r.error);
    b = std::move(*r.value);
  }
  /// The binding of slices [z0, z1) of `buf`, which holds slices from `first` on:
  /// offset rounded down to the alignment; `base` = linear voxel index of the binding start.
  BufferRange window(const GpuBuffer& buf, int first, int z0, int z1, gpu::uint& base) const {
    const std::uint64_t b = std::uint64_t(z0 - first) * slice_bytes(), e = std::uint64_t(z1 - first) * slice_bytes();
    const std::uint64_t off = b / align * align;
    base = gpu::uint(std::uint64_t(first) * slice_bytes() / 4 + off / 4);
    return {buf.handle(), off, e - off};
  }
};

BrushEngine::BrushEngine(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
BrushEngine::~BrushEngine() = default;
const core::Grid& BrushEngine::grid() const { return impl_->grid; }
const std::string& BrushEngine::device_type() const { return impl_->type; }

Result<std::unique_ptr<BrushEngine>> BrushEngine::create(VulkanContext& ctx, const Volume& vol,
                                                         std::uint64_t max_binding_bytes) {
  using R = Result<std::unique_ptr<BrushEngine>>;
  const core::Grid& g = vol.grid;
  if (g.empty() || vol.voxels.size() != g.voxel_count())
    return R::fail(vol.path + ": brush engine: " + std::to_string(vol.voxels.size()) + " voxels for dims " +
                   std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" + std::to_string(g.dims[2]));
  if (g.voxel_count() >= (std::uint64_t(1) << 32))
    return R::fail(vol.path + ": brush engine: " + std::to_string(g.voxel_count()) +
                   " voxels; the shader indexes at most 2^32");
  const auto& lim = ctx.properties().limits;
  if (lim.maxComputeWorkGroupInvocations < 512 || lim.maxComputeWorkGroupSize[2] < ISOTOUCH_BRUSH_WG)
    return R::fail("brush engine: an 8x8x8 workgroup is too large for " + ctx.info().name);
  auto impl = std::make_unique<Impl>(ctx, vol);
  impl->align = std::max<std::uint64_t>(lim.minStorageBufferOffsetAlignment, 4);
  impl->limit = ctx.max_binding_bytes();
  if (max_binding_bytes) impl->limit = std::min<std::uint64_t>(impl->limit, max_binding_bytes);
  const std::uint64_t layer_window = std::uint64_t(core::kBrickSize + 2) * impl->slice_bytes() + impl->align;
  if (layer_window > impl->limit)
    return R::fail(vol.path + ": brush engine: one brick layer's window (" + std::to_string(layer_window) +
                   " bytes: 8 slices + 2 halo) exceeds a binding of " + std::to_string(impl->limit) + " bytes");
  const std::uint64_t bytes = std::uint64_t(g.voxel_count()) * 4;
  auto dev = GpuBuffer::create(ctx, bytes, MemoryIntent::DeviceLocal, "brush volume");
  if (!dev) return R::fail(vol.path + ": brush engine: " + dev.error);
  impl->vol = std::move(*dev.value);
  auto up = GpuBuffer::create(ctx, bytes, MemoryIntent::Upload, "brush volume staging");
  if (!up) return R::fail(vol.path + ": brush engine: " + up.error);
  std::memcpy(up.value->mapped(), vol.voxels.data(), bytes);
  VkCommandBuffer cmd = ctx.begin_commands();
  record_copy(cmd, *up.value, impl->vol, bytes);
  barrier_transfer_to_compute(cmd);
  ctx.submit_and_wait(cmd);
  return R::ok(std::unique_ptr<BrushEngine>(new BrushEngine(std::move(impl))));
}

Result<std::unique_ptr<BrushEngine>> make_gpu_brush_engine(VulkanContext& ctx, const Volume& vol,
                                                           std::uint64_t max_binding_bytes) {
  return BrushEngine::create(ctx, vol, max_binding_bytes);
}

BrushResult BrushEngine::apply(const Brush& b, Volume* host) {
  const auto t0 = std::chrono::steady_clock::now();
  if (std::string e = validate(b); !e.empty()) throw BrushError(e);
  Impl& m = *impl_;
  const core::Grid& g = m.grid;
  if (host && (host->grid.dims != g.dims || host->voxels.size() != g.voxel_count()))
    throw VolumeError(host->path + ": brush engine: the host mirror's dims differ from the device volume's");
  BrushResult res;
  res.on_device = true;
  const BrickRange r = touched_range(g, b);
  res.touched = touched_bricks(g, b);
  if (r.empty()) return res;
  const int K = core::kBrickSize;
  const int nz = g.dims[2];
  const bool smooth = b.kind == BrushKind::kSmooth;
  const std::uint64_t slice = m.slice_bytes();
  const int box_bx = r.hi[0] - r.lo[0], box_by = r.hi[1] - r.lo[1], box_bz = r.hi[2] - r.lo[2];
  const std::size_t nflags = r.count();

  // z-chunks of brick layers whose window (+ 1 slice each side for smooth) fits a binding.
  const int per_chunk = std::max(int(((m.limit - m.align) / slice - 2) / std::uint64_t(K)), 1);  // create() checked >= 1
  // Pre-edit copy for smooth: the touched voxel box + 1 voxel (clipped), compact.
  const PreBox pb = pre_box(g, r);
  const std::uint64_t pre_slice = std::uint64_t(pb.hi[0] - pb.lo[0]) * std::uint64_t(pb.hi[1] - pb.lo[1]) * 4;
  if (smooth) m.ensure(m.scratch, std::uint64_t(pb.hi[2] - pb.lo[2]) * pre_slice, MemoryIntent::DeviceLocal,
                       "brush pre-edit copy");
  else m.ensure(m.scratch, 16, MemoryIntent::DeviceLocal, "brush pre-edit copy");
  m.ensure(m.flags, nflags * 4, MemoryIntent::DeviceLocal, "brush dirty flags");
  m.ensure(m.flags_down, nflags * 4, MemoryIntent::Readback, "brush dirty flags readback");
  // The box of touched voxels, for the host mirror.
  const int vx0 = r.lo[0] * K, vy0 = r.lo[1] * K, vz0 = r.lo[2] * K;
  const int vx1 = std::min(r.hi[0] * K, g.dims[0]), vy1 = std::min(r.hi[1] * K, g.dims[1]),
            vz1 = std::min(r.hi[2] * K, nz);
  const std::uint64_t row = std::uint64_t(vx1 - vx0) * 4;
  if (host) m.ensure(m.box_down, row * std::uint64_t(vy1 - vy0) * std::uint64_t(vz1 - vz0), MemoryIntent::Readback,
                     "brush box readback");

  const int chunks = (box_bz + per_chunk - 1) / per_chunk;
  DescriptorArena& arena = m.arena_for(std::uint32_t(chunks));
  GpuTimer& timer = m.timer;
  VkCommandBuffer cmd = m.ctx.begin_commands();
  timer.record_reset(cmd);
  if (smooth) {
    std::vector<VkBufferCopy> rows;
    const std::uint64_t w = std::uint64_t(pb.hi[0] - pb.lo[0]) * 4;
    std::uint64_t dst = 0;
    for (int z = pb.lo[2]; z < pb.hi[2]; ++z)
      for (int y = pb.lo[1]; y < pb.hi[1]; ++y, dst += w) rows.push_back({std::uint64_t(g.index(pb.lo[0], y, z)) * 4, dst, w});
    vkCmdCopyBuffer(cmd, m.vol.handle(), m.scratch.handle(), std::uint32_t(rows.size()), rows.data());
  }
  vkCmdFillBuffer(cmd, m.flags.handle(), 0, nflags * 4, 0);
  barrier_transfer_to_compute(cmd);
  timer.mark(cmd, 0);
  gpu::BrushPush pc = make_brush_push(g, b);
  pc.b0x = gpu::uint(r.lo[0]);
  pc.b0y = gpu::uint(r.lo[1]);
  pc.box_bx = gpu::uint(box_bx);
  pc.box_by = gpu::uint(box_by);
  pc.box_b0z = gpu::uint(r.lo[2]);
  pc.pre_x0 = gpu::uint(pb.lo[0]);
  pc.pre_y0 = gpu::uint(pb.lo[1]);
  pc.pre_z0 = gpu::uint(pb.lo[2]);
  pc.pre_w = gpu::uint(pb.hi[0] - pb.lo[0]);
  pc.pre_h = gpu::uint(pb.hi[1] - pb.lo[1]);
  for (int c = 0; c < chunks; ++c) {
    const int bz0 = r.lo[2] + c * per_chunk, bz1 = std::min(bz0 + per_chunk, r.hi[2]);
    const int z0 = bz0 * K, z1 = std::min(bz1 * K, nz);
    if (c) barrier_compute_to_compute(cmd);
    pc.b0z = gpu::uint(bz0);
    const BufferRange vw = m.window(m.vol, 0, z0, z1, pc.vol_base);
    BufferRange sw{m.scratch.handle(), 0, m.scratch.size()};
    pc.src_base = 0;
    if (smooth) {
      const std::uint64_t b0 = std::uint64_t(std::max(z0 - 1, 0) - pb.lo[2]) * pre_slice;
      const std::uint64_t e0 = std::uint64_t(std::min(z1 + 1, nz) - pb.lo[2]) * pre_slice;
      const std::uint64_t off = b0 / m.align * m.align;
      sw = {m.scratch.handle(), off, e0 - off};
      pc.src_base = gpu::uint(off / 4);
    }
    m.pipe.bind(cmd, arena, {vw, sw, BufferRange{m.flags.handle(), 0, m.flags.size()}});
    m.pipe.push(cmd, pc);
    vkCmdDispatch(cmd, std::uint32_t(box_bx), std::uint32_t(box_by), std::uint32_t(bz1 - bz0));
  }
  timer.mark(cmd, 1);
  barrier_compute_to_transfer(cmd);
  const VkBufferCopy fc{0, 0, nflags * 4};
  vkCmdCopyBuffer(cmd, m.flags.handle(), m.flags_down.handle(), 1, &fc);
  if (host) {
    std::vector<VkBufferCopy> rows;
    rows.reserve(std::size_t(vy1 - vy0) * std::size_t(vz1 - vz0));
    std::uint64_t dst = 0;
    for (int z = vz0; z < vz1; ++z)
      for (int y = vy0; y < vy1; ++y, dst += row) rows.push_back({std::uint64_t(g.index(vx0, y, z)) * 4, dst, row});
    vkCmdCopyBuffer(cmd, m.vol.handle(), m.box_down.handle(), std::uint32_t(rows.size()), rows.data());
  }
  barrier_transfer_to_host(cmd);
  m.ctx.submit_and_wait(cmd);
  res.gpu_ms = timer.elapsed_ms(0, 1);
  res.dispatches = std::size_t(chunks);

  const auto* f = static_cast<const std::uint32_t*>(m.flags_down.mapped());
  for (std::size_t i = 0; i < nflags; ++i)
    if (f[i]) res.dirty.push_back(res.touched[i]);  // both ascending, x fastest over the box
  if (host) {
    const auto* box = static_cast<const float*>(m.box_down.mapped());
    for (std::uint32_t id : res.dirty) {
      const BrickBox bb = brick_box(g, id);
      for (int z = bb.lo[2]; z < bb.hi[2]; ++z)
        for (int y = bb.lo[1]; y < bb.hi[1]; ++y) {
          const std::size_t src = (std::size_t(z - vz0) * std::size_t(vy1 - vy0) + std::size_t(y - vy0)) *
                                      std::size_t(vx1 - vx0) + std::size_t(bb.lo[0] - vx0);
          std::memcpy(host->voxels.data() + g.index(bb.lo[0], y, z), box + src,
                      std::size_t(bb.hi[0] - bb.lo[0]) * 4);
        }
    }
  }
  res.wall_ms = ms_since(t0);
  return res;
}

void BrushEngine::upload_bricks(const Volume& vol, const std::vector<std::uint32_t>& ids) {
  Impl& m = *impl_;
  if (vol.grid.dims != m.grid.dims || vol.voxels.size() != m.grid.voxel_count())
    throw VolumeError(vol.path + ": brush engine: upload from a volume whose dims differ from the device volume's");
  if (ids.empty()) return;
  std::uint64_t bytes = 0;
  for (std::uint32_t id : ids) bytes += brick_box(m.grid, id).voxels() * 4;
  m.ensure(m.upload, bytes, MemoryIntent::Upload, "brush brick upload staging");
  std::vector<VkBufferCopy> rows;
  auto* dst = static_cast<float*>(m.upload.mapped());
  std::uint64_t at = 0;
  for (std::uint32_t id : ids) {
    const BrickBox bb = brick_box(m.grid, id);
    const std::size_t n = std::size_t(bb.hi[0] - bb.lo[0]);
    for (int z = bb.lo[2]; z < bb.hi[2]; ++z)
      for (int y = bb.lo[1]; y < bb.hi[1]; ++y) {
        const std::size_t v = m.grid.index(bb.lo[0], y, z);
        std::memcpy(dst + at / 4, vol.voxels.data() + v, n * 4);
        rows.push_back({at, std::uint64_t(v) * 4, n * 4});
        at += n * 4;
      }
  }
  VkCommandBuffer cmd = m.ctx.begin_commands();
  vkCmdCopyBuffer(cmd, m.upload.handle(), m.vol.handle(), std::uint32_t(rows.size()), rows.data());
  barrier_transfer_to_compute(cmd);
  m.ctx.submit_and_wait(cmd);
}

std::vector<float> BrushEngine::download_all() {
  Impl& m = *impl_;
  const std::uint64_t bytes = std::uint64_t(m.grid.voxel_count()) * 4;
  GpuBuffer down = make_buffer_or_throw(m.ctx, bytes, MemoryIntent::Readback, "brush volume readback");
  VkCommandBuffer cmd = m.ctx.begin_commands();
  record_copy(cmd, m.vol, down, bytes);
  barrier_transfer_to_host(cmd);
  m.ctx.submit_and_wait(cmd);
  std::vector<float> out(m.grid.voxel_count());
  std::memcpy(out.data(), down.mapped(), bytes);
  return out;
}

}  // namespace isotouch::session
