#include "isotouch/engine/passes.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <sstream>
#include <stdexcept>

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/gradient_pass.h"
#include "isotouch/shaders/brick_minmax_spv.h"
#include "isotouch/shaders/gaussian1d_spv.h"
#include "isotouch/shaders/filter_x4_spv.h"
#include "isotouch/shaders/gauss_axis_x4_spv.h"
#include "isotouch/shaders/minmax_segments_spv.h"
#include "isotouch/shaders/minmax_slices_spv.h"
#include "isotouch/shaders/minmax_bricks_spv.h"
#include "isotouch/shaders/minmax_rows_spv.h"
#include "isotouch/shaders/morph1d_spv.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/vk_resources.h"

namespace isotouch::engine {

static_assert(sizeof(gpu::Filter1dPush) == 48, "Filter1dPush: 12 4-byte members (std430)");
static_assert(sizeof(gpu::BrickMinMaxPush) == 48, "BrickMinMaxPush: 12 4-byte members (std430)");

std::vector<std::uint32_t> fused_gaussian_spec(const std::array<int, 3>& dims,
                                               const std::array<std::vector<float>, 3>& kernels) {
  constexpr std::size_t kTaps = 2 * ISOTOUCH_FUSED_MAX_RADIUS + 1;
  std::vector<std::uint32_t> spec(6 + 3 * kTaps, 0u);
  for (std::size_t a = 0; a < 3; ++a) {
    if (kernels[a].size() > kTaps) throw std::logic_error("fused_gaussian_spec: kernel wider than the fused shader");
    spec[a] = std::uint32_t(dims[a]);
    spec[3 + a] = std::uint32_t(kernels[a].size() / 2);
    std::memcpy(&spec[6 + a * kTaps], kernels[a].data(), kernels[a].size() * 4);
  }
  return spec;
}

namespace {
bool has(const std::vector<PassDesc>& p, PassKind k) {
  return std::any_of(p.begin(), p.end(), [k](const PassDesc& d) { return d.kind == k; });
}
std::uint32_t groups(std::uint64_t n, std::uint32_t wg) { return std::uint32_t((n + wg - 1) / wg); }
std::uint64_t floats_before(std::uint64_t z, const void* user) {  // slices of float
  return z * *static_cast<const std::uint64_t*>(user);
}
struct BrickLayer {
  std::uint64_t bytes_per_layer;  // bx * by * 2 floats
};
std::uint64_t bricks_before(std::uint64_t z, const void* user) {
  return (z + ISOTOUCH_BRICK - 1) / ISOTOUCH_BRICK * static_cast<const BrickLayer*>(user)->bytes_per_layer;
}
double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

namespace {
/// One step of a chain's recording: a filter axis, a whole-field Gaussian axis, the gradient or the
/// brick min/max, with its z-slabs.
struct ChainStep {
  std::size_t pass;
  const ComputePipelineBase* pipe = nullptr;
  /// MinMaxSegments: the brick min/max over the whole field in two dispatches, each slice's
  /// brick row segments (minmax_segments) and then the bricks (minmax_slices).
  /// GaussAxis: one axis of a Gaussian over the whole field (gauss_axis_x4).
  enum { Filter, GaussAxis, Gradient, MinMax, MinMaxSegments } type = Filter;
  gpu::Filter1dPush f{};
  const ComputePipeline<gpu::DensePush>* x4 = nullptr;         // filter_x4 variant, else the 1-D filter
  const ComputePipeline<gpu::Filter1dPush>* f1d = nullptr;     // gaussian1d (reads the weights) or morph1d
  std::vector<Slab> slabs;
};
/// Every buffer of one run (absent ones empty), kept by name for the next run.
struct ChainBuffers {
  GpuBuffer field[2], up, w_dev, w_up, samples, samples_down, bricks, bricks_down, field_down, rows, segments;
};
/// What the dispatches of one slab need besides the step: sizes, the brick min/max pair,
/// the buffers they bind.
struct SlabArgs {
  int nx, ny, nz;
  std::uint32_t bx, by;
  const ComputePipeline<gpu::BrickMinMaxPush>*mm_rows, *mm_bricks, *minmax_legacy;
  const ComputePipeline<gpu::DensePush>* mm_segments;      // minmax_segments, if that form runs
  const ComputePipeline<gpu::BrickMinMaxPush>* mm_slices;  // minmax_slices, with it
  const ChainBuffers* b;
  const VkPhysicalDeviceLimits* lim;
  int halo;
  core::Grid grid;
};

/// The brick min/max's push constants for slab `sl` (brick_minmax, minmax_rows/_bricks,
/// minmax_slices).
gpu::BrickMinMaxPush brick_minmax_push(const Slab& sl, const SlabArgs& a) {
  gpu::BrickMinMaxPush pc{};
  pc.nx = gpu::uint(a.nx);
  pc.ny = gpu::uint(a.ny);
  pc.nz = gpu::uint(a.nz);
  pc.bx = a.bx;
  pc.by = a.by;
  pc.bz0 = gpu::uint(sl.z0 / ISOTOUCH_BRICK);
  pc.slab_bz = gpu::uint((sl.nz + ISOTOUCH_BRICK - 1) / ISOTOUCH_BRICK);
  pc.src_z0 = gpu::uint(sl.src_z0);
  pc.src_offset = gpu::uint(sl.src_offset_elems);
  pc.dst_offset = gpu::uint(sl.dst_offset_elems);
  pc.halo = gpu::uint(a.halo);
  return pc;
}

/// Records the dispatches of one slab of step `s` (no barrier after the last).
void record_slab(VkCommandBuffer cmd, DescriptorArena& arena, const ChainStep& s, const Slab& sl, const SlabArgs& a) {
  const int nx = a.nx, ny = a.ny, nz = a.nz;
  if (s.type == ChainStep::MinMaxSegments) {
    const BufferRange seg{a.b->segments.handle(), 0, a.b->segments.size()};
    a.mm_segments->bind(cmd, arena, {sl.src, seg, sl.src});  // the field as quads and as floats
    vkCmdDispatch(cmd, groups(std::uint64_t(a.bx) * a.by, ISOTOUCH_DENSE_WG), 1, std::uint32_t(nz));
    barrier_compute_to_compute(cmd);
    const gpu::BrickMinMaxPush pc = brick_minmax_push(sl, a);  // the whole volume: bz0 = 0
    a.mm_slices->bind(cmd, arena, {seg, sl.dst});
    a.mm_slices->push(cmd, pc);
    vkCmdDispatch(cmd, groups(std::uint64_t(a.bx) * a.by, ISOTOUCH_DENSE_WG), 1, pc.slab_bz);
  } else if (s.type == ChainStep::GaussAxis) {
    s.pipe->bind(cmd, arena, {sl.src, sl.dst});
    vkCmdDispatch(cmd, groups(std::uint64_t(nx) / ISOTOUCH_DENSE_VOXELS, ISOTOUCH_DENSE_WG), std::uint32_t(ny),
                  std::uint32_t(nz));
  } else if (s.type == ChainStep::Filter && s.x4) {
    gpu::DensePush pc{};
    pc.nx = s.f.nx;
    pc.ny = s.f.ny;
    pc.nz = s.f.nz;
    pc.z0 = gpu::uint(sl.z0);
    pc.slab_nz = gpu::uint(sl.nz);
    pc.src_z0 = gpu::uint(sl.src_z0);
    pc.src_offset = gpu::uint(sl.src_offset_elems);
    pc.dst_offset = gpu::uint(sl.dst_offset_elems);
    pc.qx = gpu::uint((std::uint64_t(nx) + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS);
    // One vec4 store per invocation when every row starts on a 16-byte boundary.
    pc.vec4_out = (nx % ISOTOUCH_DENSE_VOXELS == 0 && sl.dst_offset_elems % ISOTOUCH_DENSE_VOXELS == 0) ? 1u : 0u;
    s.x4->bind(cmd, arena, {sl.src, sl.dst});
    s.x4->push(cmd, pc);
    vkCmdDispatch(cmd, groups(std::uint64_t(pc.qx) * std::uint64_t(ny), ISOTOUCH_DENSE_WG), 1, std::uint32_t(sl.nz));
  } else if (s.type == ChainStep::Filter) {
    gpu::Filter1dPush pc = s.f;
    pc.z0 = gpu::uint(sl.z0);
    pc.slab_nz = gpu::uint(sl.nz);
    pc.src_z0 = gpu::uint(sl.src_z0);
    pc.src_offset = gpu::uint(sl.src_offset_elems);
    pc.dst_offset = gpu::uint(sl.dst_offset_elems);
    if (s.f1d->bindings() == 3)  // gaussian1d: the weights buffer
      s.f1d->bind(cmd, arena, {sl.src, sl.dst, BufferRange{a.b->w_dev.handle(), 0, a.b->w_dev.size()}});
    else
      s.f1d->bind(cmd, arena, {sl.src, sl.dst});
    s.f1d->push(cmd, pc);
    vkCmdDispatch(cmd, groups(std::uint64_t(nx), ISOTOUCH_FILTER_WG_X), groups(std::uint64_t(ny), ISOTOUCH_FILTER_WG_Y),
                  groups(sl.nz, ISOTOUCH_FILTER_WG_Z));
  } else if (s.type == ChainStep::MinMax) {
    gpu::BrickMinMaxPush pc = brick_minmax_push(sl, a);
    if (a.mm_rows) {
      const std::uint64_t src_nz = sl.src_z1 - sl.src_z0;
      const BufferRange rr{a.b->rows.handle(), 0, src_nz * std::uint64_t(ny) * a.bx * 8};
      pc.pad0 = gpu::uint(src_nz);
      a.mm_rows->bind(cmd, arena, {sl.src, rr});
      a.mm_rows->push(cmd, pc);
      vkCmdDispatch(cmd, groups(std::uint64_t(a.bx) * std::uint64_t(ny), ISOTOUCH_DENSE_WG), 1, std::uint32_t(src_nz));
      barrier_compute_to_compute(cmd);
      a.mm_bricks->bind(cmd, arena, {rr, sl.dst});
      a.mm_bricks->push(cmd, pc);
      vkCmdDispatch(cmd, groups(std::uint64_t(a.bx) * a.by, ISOTOUCH_DENSE_WG), 1, pc.slab_bz);
      barrier_compute_to_compute(cmd);  // the next slab rewrites the row ranges
    } else {
      a.minmax_legacy->bind(cmd, arena, {sl.src, sl.dst});
      a.minmax_legacy->push(cmd, pc);
      vkCmdDispatch(cmd, groups(a.bx, ISOTOUCH_MINMAX_WG_X), groups(a.by, ISOTOUCH_MINMAX_WG_Y),
                    groups(pc.slab_bz, ISOTOUCH_MINMAX_WG_Z));
    }
  }
}

/// The outputs of a finished run into `out` (copies), or their addresses into `in_place`
/// where the buffers are host-visible; `cur` the field after the last filter.
void read_outputs(const Volume& vol, const std::vector<PassDesc>& passes, const ChainBuffers& b, int cur, bool direct,
                  bool filters, const std::array<std::uint32_t, 3>& nb, PassChain::InPlace* in_place,
                  ChainOutput& out) {
  const std::uint64_t n = vol.grid.voxel_count();
  if (filters && in_place && direct) {
    in_place->field = static_cast<const float*>(b.field[cur].mapped());
  } else if (filters) {
    out.field.emplace(n);
    std::memcpy(out.field->data(), direct ? b.field[cur].mapped() : b.field_down.mapped(), n * 4);
  }
  if (b.samples && in_place && direct) {
    in_place->samples = static_cast<const core::Sample*>(b.samples.mapped());
  } else if (b.samples) {
    out.samples.emplace();
    out.samples->grid = vol.grid;
    out.samples->samples.resize(n);
    std::memcpy(out.samples->samples.data(), direct ? b.samples.mapped() : b.samples_down.mapped(),
                n * sizeof(core::Sample));
  }
  if (b.bricks) {
    BrickRanges r;
    r.bricks = {int(nb[0]), int(nb[1]), int(nb[2])};
    for (const PassDesc& p : passes)
      if (p.kind == PassKind::BrickMinMax) r.halo = p.halo;
    const std::size_t count = std::size_t(nb[0]) * nb[1] * nb[2];
    r.min.resize(count);
    r.max.resize(count);
    const float* f = static_cast<const float*>(direct ? b.bricks.mapped() : b.bricks_down.mapped());
    for (std::size_t i = 0; i < count; ++i) {
      r.min[i] = f[2 * i];
      r.max[i] = f[2 * i + 1];
    }
    out.bricks = std::move(r);
  }
}

/// Keeps this run's buffers by name for the next run of the same sizes.
void keep_buffers(ChainBuffers& b, std::map<std::string, GpuBuffer>& kept) {
  kept.clear();
  auto keep = [&](GpuBuffer& g, const char* what) {
    if (g) kept[what] = std::move(g);
  };
  keep(b.field[0], "voxels");
  keep(b.field[1], "field ping-pong");
  keep(b.up, "voxels staging");
  keep(b.w_dev, "gaussian weights");
  keep(b.w_up, "gaussian weights staging");
  keep(b.samples, "samples");
  keep(b.samples_down, "samples readback");
  keep(b.bricks, "brick ranges");
  keep(b.bricks_down, "brick ranges readback");
  keep(b.field_down, "field readback");
  keep(b.rows, "brick row ranges");
  keep(b.segments, "brick slice segments");
}
}  // namespace

struct PassChain::Impl {
  VulkanContext& ctx;
  ShaderSet shaders = ShaderSet::Current;
  std::unique_ptr<ComputePipeline<gpu::Filter1dPush>> gauss, morph;
  /// filter_x4 variants by specialization (size, axis, radius, weights, mode), made on first use.
  std::map<std::vector<std::uint32_t>, std::unique_ptr<ComputePipeline<gpu::DensePush>>> gauss_x4;
  /// `w`: the Gaussian's weights (mode 0), else empty; `mode` 0 or ISOTOUCH_MORPH_MAX / MIN.
  /// `vec4_in`: the source viewed as quads (quad_slabs()).
  const ComputePipeline<gpu::DensePush>* filter_x4(const std::array<int, 3>& dims, int axis, int radius,
                                                   std::uint32_t mode, const std::vector<float>& w, bool vec4_in) {
    std::vector<std::uint32_t> spec(6 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 2, 0u);
    for (int a = 0; a < 3; ++a) spec[std::size_t(a)] = std::uint32_t(dims[std::size_t(a)]);
    spec[3] = std::uint32_t(axis);
    spec[4] = std::uint32_t(radius);
    for (std::size_t k = 0; k < w.size(); ++k) std::memcpy(&spec[5 + k], &w[k], 4);
    spec[5 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 1] = mode;  // constant_id 38
    spec[5 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 2] = vec4_in ? 1u : 0u;  // constant_id 39
    auto& p = gauss_x4[spec];
    if (!p) {
      p = std::make_unique<ComputePipeline<gpu::DensePush>>(ctx, filter_x4_spv, 2, mode ? "morph_x4" : "gaussian_x4",
                                                            0u, spec, 1u);
      if (vec4_in) p->set_texel_vec4(1u);
    }
    return p.get();
  }
  /// gauss_axis_x4 variants by specialization (size, axis, radius, weights), made on first use.
  std::map<std::vector<std::uint32_t>, std::unique_ptr<ComputePipeline<gpu::DensePush>>> gauss_axis;
  std::unique_ptr<ComputePipeline<gpu::BrickMinMaxPush>> minmax;
  /// Current set's brick min/max in two steps (minmax_rows, minmax_bricks), specialised on
  /// the bricks along x; made on first use.
  std::map<std::uint32_t, std::pair<std::unique_ptr<ComputePipeline<gpu::BrickMinMaxPush>>,
                                    std::unique_ptr<ComputePipeline<gpu::BrickMinMaxPush>>>> minmax_x4;
  std::unique_ptr<GradientPass> gradient;
  /// The brick min/max over the whole field (minmax_segments by volume size, then
  /// minmax_slices), made on first use.
  std::map<std::array<int, 3>, std::unique_ptr<ComputePipeline<gpu::DensePush>>> mm_segments;
  std::unique_ptr<ComputePipeline<gpu::BrickMinMaxPush>> mm_slices;
  std::string last_run;
  /// The last run's buffers by name, reused by the next run of the same sizes: no new
  /// allocation, and no first-touch page faults inside the timed dispatches.
  std::map<std::string, GpuBuffer> kept;
  explicit Impl(VulkanContext& c) : ctx(c) {}
};

PassChain::PassChain(std::unique_ptr<Impl> impl, std::vector<PassDesc> passes)
    : impl_(std::move(impl)), passes_(std::move(passes)) {}
PassChain::~PassChain() = default;

Result<std::unique_ptr<PassChain>> PassChain::create(VulkanContext& ctx, std::vector<PassDesc> passes,
                                                     ShaderSet shaders) {
  using R = Result<std::unique_ptr<PassChain>>;
  if (std::string e = validate_passes(passes); !e.empty()) return R::fail("pass chain: " + e);
  auto impl = std::make_unique<Impl>(ctx);
  impl->shaders = shaders;
  // Only the pipelines the list needs.
  if (has(passes, PassKind::Gaussian) && shaders == ShaderSet::Legacy)
    impl->gauss = std::make_unique<ComputePipeline<gpu::Filter1dPush>>(ctx, gaussian1d_spv, 3, "gaussian1d");
  if (has(passes, PassKind::Closing) && shaders == ShaderSet::Legacy)
    impl->morph = std::make_unique<ComputePipeline<gpu::Filter1dPush>>(ctx, morph1d_spv, 2, "morph1d");
  if (has(passes, PassKind::BrickMinMax) && shaders == ShaderSet::Legacy)
    impl->minmax = std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(ctx, brick_minmax_spv, 2, "brick_minmax");
  if (has(passes, PassKind::Gradient)) impl->gradient = std::make_unique<GradientPass>(ctx, shaders);
  return R::ok(std::unique_ptr<PassChain>(new PassChain(std::move(impl), std::move(passes))));
}

std::string PassChain::describe() const {
  std::ostringstream s;
  s << "passes:";
  for (std::size_t i = 0; i < passes_.size(); ++i) s << (i ? " -> " : " ") << passes_[i].label();
  const bool filters = has(passes_, PassKind::Gaussian) || has(passes_, PassKind::Closing);
  const bool gauss = has(passes_, PassKind::Gaussian);
  const bool legacy = impl_->shaders == ShaderSet::Legacy;
  // The filters' pipelines: filter_x4 variants, "gaussian_x4" / "morph_x4" (made per kernel
  // on first run; a radius above ISOTOUCH_DENSE_MAX_RADIUS takes gaussian1d / morph1d), or
  // gaussian1d / morph1d with the legacy set.
  const bool closing = has(passes_, PassKind::Closing);
  const bool minmax = has(passes_, PassKind::BrickMinMax);
  // The brick min/max over the whole field (made on the first run it fits; a run where it
  // does not - the binding limit, rows not of whole quads - takes row ranges by slab).
  const bool seg_mm = !impl_->mm_segments.empty() && impl_->minmax_x4.empty();
  const char* gname = legacy ? " gaussian1d" : " gaussian_x4";
  const char* mname = legacy ? " morph1d" : " morph_x4";
  s << "\nshaders: " << shader_set_name(impl_->shaders) << (legacy ? "" : " (texel-buffer input, 4 voxels per invocation)");
  s << "\npipelines created:" << (gauss ? (impl_->gauss_axis.empty() ? gname : " gauss_axis_x4") : "")
    << (gauss && !impl_->gauss_axis.empty() && !impl_->gauss_x4.empty() ? " gaussian_x4" : "") << (!legacy && impl_->gauss ? " gaussian1d" : "")
    << (closing ? mname : "") << (!legacy && impl_->morph ? " morph1d" : "")
    << (impl_->gradient ? (legacy ? " gradient" : " gradient_x4") : "")
    << (minmax ? (legacy ? " brick_minmax"
                         : seg_mm ? " brick_minmax (minmax_segments + minmax_slices)"
                                    : " brick_minmax (minmax_rows + minmax_bricks)")
               : "");
  const bool all = gauss && closing && impl_->gradient && minmax;
  s << "\nleft out (not created, not run):" << (gauss ? "" : gname) << (closing ? "" : (legacy ? " morph1d" : " morph_x4 morph1d"))
    << (impl_->gradient ? "" : " gradient") << (minmax ? "" : " brick_minmax") << (all ? " none" : "");
  const bool direct = impl_->ctx.device_local_is_host_visible();
  s << "\nbuffers per run: voxels (float, device-local)" << (direct ? " written in place (host-visible: no staging)" : " + staging")
    << (filters ? ", ping-pong field (float)" : "") << (filters && !direct ? ", field readback" : "")
    << (impl_->gauss ? ", gaussian weights (+ staging)" : "")
    << (impl_->gradient ? (direct ? ", samples (vec4, read in place)" : ", samples (vec4) + readback") : "")
    << (minmax ? (direct ? ", brick ranges (read in place)" : ", brick ranges + readback") : "")
    << (minmax && !legacy && !seg_mm ? ", brick row ranges (8 B per brick column and row of a slab)" : "")
    << (seg_mm ? ", brick slice segments (8 B per brick segment of a slice)" : "");
  s << "\nleft out buffers:" << (filters ? "" : " ping-pong field, field readback")
    << (impl_->gauss ? "" : " gaussian weights") << (impl_->gradient ? "" : " samples (16 B/voxel)")
    << (minmax ? "" : " brick ranges") << (direct ? " staging and readback copies" : "") << (all ? " none" : "");
  if (!impl_->last_run.empty()) s << "\nlast run:\n" << impl_->last_run;
  return s.str();
}

ChainOutput PassChain::run(const Volume& vol, std::uint64_t max_binding_bytes) {
  return run_impl(vol, max_binding_bytes, nullptr);
}

ChainOutput PassChain::run_in_place(const Volume& vol, InPlace& where, std::uint64_t max_binding_bytes) {
  where = {};
  ChainOutput out = run_impl(vol, max_binding_bytes, &where);
  if (!where.field && out.field) where.field = out.field->data();
  if (!where.samples && out.samples) where.samples = out.samples->samples.data();
  return out;
}

namespace {

/// Throws when a row of slices needs more workgroups than one dispatch may have.
void check_dispatch_width(VulkanContext& ctx, const Volume& vol) {
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1];
  const auto& lim = ctx.properties().limits;
  if (groups(std::uint64_t(nx), ISOTOUCH_FILTER_WG_X) > lim.maxComputeWorkGroupCount[0] ||
      groups(std::uint64_t(ny), ISOTOUCH_FILTER_WG_Y) > lim.maxComputeWorkGroupCount[1])
    throw VolumeError(vol.path + ": volume too wide for one dispatch on " + ctx.info().name);
  if (groups((std::uint64_t(nx) + ISOTOUCH_DENSE_VOXELS - 1) / ISOTOUCH_DENSE_VOXELS * std::uint64_t(ny), ISOTOUCH_DENSE_WG) >
      lim.maxComputeWorkGroupCount[0])
    throw VolumeError(vol.path + ": volume too wide for one dispatch on " + ctx.info().name);
}

/// A buffer for this run: the last run's buffer of the same name when its size, intent and
/// mapping still fit (no new allocation), else a new one.
struct BufferSource {
  VulkanContext& ctx;
  std::map<std::string, GpuBuffer>& kept;
  const std::string& path;
  GpuBuffer operator()(std::uint64_t bytes, MemoryIntent intent, const char* what) const {
    if (auto it = kept.find(what); it != kept.end()) {
      GpuBuffer b = std::move(it->second);
      kept.erase(it);
      const bool mapped_as_now = intent != MemoryIntent::DeviceLocal ||
                                 (b.mapped() != nullptr) == ctx.device_local_is_host_visible();
      if (b.size() == bytes && b.intent() == intent && mapped_as_now) return b;
    }
    auto r = GpuBuffer::create(ctx, bytes, intent, what);
    if (!r) throw VolumeError(path + ": " + r.error);
    return std::move(*r.value);
  }
};

/// The filters' parameters in voxels: each Gaussian's kernels (their weights packed in one
/// array, with each axis's offset) and each closing's radii.
struct FilterParams {
  std::vector<GaussianAxes> gaussians;
  std::vector<std::array<int, 3>> closings;
  std::vector<float> weights;
  std::vector<std::array<std::uint32_t, 3>> w_offsets;
};

/// Validated (and too-wide kernels rejected) before any allocation.
FilterParams filter_params(const Volume& vol, const std::vector<PassDesc>& passes) {
  FilterParams fp;
  try {
    for (const PassDesc& p : passes) {
      if (p.kind == PassKind::Gaussian) {
        fp.gaussians.push_back(gaussian_axes(vol.grid, p.sigma_mm));
        std::array<std::uint32_t, 3> off{};
        for (int a = 0; a < 3; ++a) {
          off[std::size_t(a)] = std::uint32_t(fp.weights.size());
          const auto& k = fp.gaussians.back().kernel[std::size_t(a)];
          fp.weights.insert(fp.weights.end(), k.begin(), k.end());
        }
        fp.w_offsets.push_back(off);
      }
      if (p.kind == PassKind::Closing) fp.closings.push_back(closing_radii(vol.grid, p.radius_mm));
    }
  } catch (const std::invalid_argument& e) {
    throw VolumeError(vol.path + ": " + e.what());
  }
  return fp;
}

/// What every planning step reads: the volume, sizes, limits and the chain's buffers.
struct ChainInput {
  VulkanContext& ctx;
  const Volume& vol;
  const FilterParams& fp;
  ChainBuffers& bufs;
  std::uint64_t n, slice_bytes, limit, max_binding_bytes;
  std::uint32_t bx, by, bz;
  bool direct, legacy, filters;
  const std::uint64_t* float_slice;  ///< SlabGeometry::user of the filters (bytes per slice)
  const BrickLayer* layer;           ///< SlabGeometry::user of the brick min/max
};

/// Allocates the run's buffers into in.bufs: the voxels and, with filters, the ping-pong
/// field; staging and readback copies only where device-local memory is not host-visible
/// (in.direct: the host writes the voxels and reads the outputs in place).
void make_buffers(const BufferSource& buffer, const std::vector<PassDesc>& passes, bool gradient, ChainInput& in) {
  ChainBuffers& b = in.bufs;
  const std::uint64_t n = in.n;
  b.field[0] = buffer(n * 4, MemoryIntent::DeviceLocal, "voxels");
  if (in.filters) b.field[1] = buffer(n * 4, MemoryIntent::DeviceLocal, "field ping-pong");
  in.direct = b.field[0].mapped() != nullptr;
  const bool direct = in.direct;
  if (!direct) b.up = buffer(n * 4, MemoryIntent::Upload, "voxels staging");
  if (!in.fp.weights.empty()) {
    b.w_dev = buffer(in.fp.weights.size() * 4, MemoryIntent::DeviceLocal, "gaussian weights");
    if (!direct) b.w_up = buffer(in.fp.weights.size() * 4, MemoryIntent::Upload, "gaussian weights staging");
  }
  if (gradient) {
    b.samples = buffer(n * sizeof(core::Sample), MemoryIntent::DeviceLocal, "samples");
    if (!direct) b.samples_down = buffer(n * sizeof(core::Sample), MemoryIntent::Readback, "samples readback");
  }
  const std::uint64_t brick_bytes = std::uint64_t(in.bx) * in.by * in.bz * 2 * 4;
  if (has(passes, PassKind::BrickMinMax)) {
    b.bricks = buffer(brick_bytes, MemoryIntent::DeviceLocal, "brick ranges");
    if (!direct) b.bricks_down = buffer(brick_bytes, MemoryIntent::Readback, "brick ranges readback");
  }
  if (in.filters && !direct) b.field_down = buffer(n * 4, MemoryIntent::Readback, "field readback");
}

/// The planned dispatches of a run, and what recording them needs.
struct ChainPlan {
  std::vector<ChainStep> steps;
  std::uint64_t rows_slices = 0;  ///< most source slices of a brick min/max slab
  std::uint32_t extra_sets = 0;   ///< the current brick min/max binds twice per slab
  int cur = 0;                    ///< the field buffer the next pass reads
  std::size_t gi = 0, ci = 0;     ///< the next Gaussian's and closing's parameters
  std::uint64_t segments_bytes = 0;  ///< the brick min/max's slice segments (minmax_segments)
  const ComputePipeline<gpu::DensePush>* mm_segments = nullptr;
  const ComputePipeline<gpu::BrickMinMaxPush>* mm_slices = nullptr;
  std::ostringstream info;        ///< describe()'s "last run" lines
};

/// A Gaussian whose radii are <= ISOTOUCH_FUSED_MAX_RADIUS runs as three whole-field passes
/// (gauss_axis_x4) where rows hold whole quads and the field is one binding and one texel view.
/// On lavapipe these separate passes beat the x, y, z fused pass (gauss_fused_list's dense
/// form): chest, device time, `bench engine`.
bool whole_field_gaussian(const ChainInput& in, const PassDesc& p, std::size_t gi) {
  const auto& lim = in.ctx.properties().limits;
  const int nx = in.vol.grid.dims[0], ny = in.vol.grid.dims[1], nz = in.vol.grid.dims[2];
  bool whole = p.kind == PassKind::Gaussian && !in.legacy && nx % int(ISOTOUCH_DENSE_VOXELS) == 0 &&
               in.n * 4 <= in.limit && in.n <= lim.maxTexelBufferElements &&
               groups(std::uint64_t(nx) / ISOTOUCH_DENSE_VOXELS, ISOTOUCH_DENSE_WG) <= lim.maxComputeWorkGroupCount[0] &&
               std::uint64_t(ny) <= lim.maxComputeWorkGroupCount[1] && std::uint64_t(nz) <= lim.maxComputeWorkGroupCount[2];
  for (int a = 0; a < 3 && whole; ++a)
    whole = in.fp.gaussians[gi].kernel[std::size_t(a)].size() <= 2 * ISOTOUCH_FUSED_MAX_RADIUS + 1;
  return whole;
}

/// The three axes of Gaussian pass i over the whole field (whole_field_gaussian), one step each.
template <class ChainImpl>
void plan_gauss_axes(ChainImpl& impl, const ChainInput& in, std::size_t i, ChainPlan& plan) {
  const auto& gauss = in.fp.gaussians[plan.gi];
  for (int axis = 0; axis < 3; ++axis) {
    const std::vector<float>& k = gauss.kernel[std::size_t(axis)];
    std::vector<std::uint32_t> spec = {std::uint32_t(in.vol.grid.dims[0]), std::uint32_t(in.vol.grid.dims[1]),
                                       std::uint32_t(in.vol.grid.dims[2]), std::uint32_t(axis),
                                       std::uint32_t(k.size() / 2)};
    spec.resize(5 + 2 * ISOTOUCH_FUSED_MAX_RADIUS + 1, 0u);
    std::memcpy(&spec[5], k.data(), k.size() * 4);
    auto& pipe = impl.gauss_axis[spec];
    if (!pipe) {
      pipe = std::make_unique<ComputePipeline<gpu::DensePush>>(in.ctx, gauss_axis_x4_spv, 2, "gauss_axis_x4", 0u, spec,
                                                               1u);
      pipe->set_texel_vec4(1u);
    }
    ChainStep s;
    s.pass = i;
    s.type = ChainStep::GaussAxis;
    s.pipe = pipe.get();
    Slab whole;
    whole.nz = std::uint64_t(in.vol.grid.dims[2]);
    whole.src_z1 = whole.nz;
    whole.src = {in.bufs.field[plan.cur].handle(), 0, in.n * 4};
    whole.dst = {in.bufs.field[1 - plan.cur].handle(), 0, in.n * 4};
    s.slabs.push_back(whole);
    plan.steps.push_back(std::move(s));
    plan.cur = 1 - plan.cur;
    plan.info << (axis ? ", " : ": ") << "xyz"[axis] << " r=" << k.size() / 2;
  }
  plan.info << " over the whole field (gauss_axis_x4; sigma " << gauss.sigma_vox[0] << ", " << gauss.sigma_vox[1]
            << ", " << gauss.sigma_vox[2] << " voxels)";
  ++plan.gi;
}

/// A brick min/max with a 1-voxel halo runs over the whole field in two dispatches
/// (minmax_segments: each slice's brick row segments; minmax_slices: the bricks) where rows
/// hold whole quads and the field and the segments each fit one binding and one texel view.
bool whole_field_minmax(const ChainInput& in, const PassDesc& p) {
  if (in.legacy || p.kind != PassKind::BrickMinMax || p.halo != 1) return false;
  const auto& lim = in.ctx.properties().limits;
  const int nx = in.vol.grid.dims[0], nz = in.vol.grid.dims[2];
  const std::uint64_t segments = std::uint64_t(in.bx) * in.by * std::uint64_t(nz) * 8;
  return nx % int(ISOTOUCH_DENSE_VOXELS) == 0 && in.n * 4 <= in.limit && segments <= in.limit &&
         in.n <= lim.maxTexelBufferElements && std::uint64_t(nz) <= lim.maxComputeWorkGroupCount[2] &&
         groups(std::uint64_t(in.bx) * in.by, ISOTOUCH_DENSE_WG) <= lim.maxComputeWorkGroupCount[0];
}

/// The brick min/max of pass i over the whole field (whole_field_minmax): one step, two
/// dispatches.
template <class ChainImpl>
void plan_whole_field_minmax(ChainImpl& impl, const ChainInput& in, std::size_t i, ChainPlan& plan) {
  const std::array<int, 3> dims = in.vol.grid.dims;
  auto& pipe = impl.mm_segments[dims];
  if (!pipe) {
    pipe = std::make_unique<ComputePipeline<gpu::DensePush>>(
        in.ctx, minmax_segments_spv, 3, "minmax_segments", 0u,
        std::vector<std::uint32_t>{std::uint32_t(dims[0]), std::uint32_t(dims[1]), std::uint32_t(dims[2])}, 0b101u);
    pipe->set_texel_vec4(1u);
  }
  if (!impl.mm_slices)
    impl.mm_slices =
        std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(in.ctx, minmax_slices_spv, 2, "minmax_slices");
  plan.mm_segments = pipe.get();
  plan.mm_slices = impl.mm_slices.get();
  plan.segments_bytes = std::uint64_t(in.bx) * in.by * std::uint64_t(dims[2]) * 8;
  Slab whole;
  whole.nz = std::uint64_t(dims[2]);
  whole.src_z1 = whole.nz;
  whole.src = {in.bufs.field[plan.cur].handle(), 0, in.n * 4};
  whole.dst = {in.bufs.bricks.handle(), 0, std::uint64_t(in.bx) * in.by * in.bz * 8};
  ChainStep m;
  m.pass = i;
  m.type = ChainStep::MinMaxSegments;
  m.pipe = pipe.get();
  m.slabs.push_back(whole);
  plan.steps.push_back(std::move(m));
  plan.extra_sets += 1;  // two descriptor sets for the one slab
  plan.info << ": " << in.bx << "x" << in.by << "x" << in.bz
            << " bricks over the whole field (minmax_segments: each slice's brick row segments; minmax_slices)";
}

/// One axis (k < 3) of a Gaussian, or of a closing (k < 3 the max, then the min).
template <class ChainImpl>
ChainStep plan_filter_axis(ChainImpl& impl, const ChainInput& in, const PassDesc& p, std::size_t i, int k,
                           ChainPlan& plan) {
  const int nx = in.vol.grid.dims[0], ny = in.vol.grid.dims[1], nz = in.vol.grid.dims[2];
  const int axis = k % 3;
  ChainStep s;
  s.pass = i;
  s.type = ChainStep::Filter;
  s.f.nx = gpu::uint(nx);
  s.f.ny = gpu::uint(ny);
  s.f.nz = gpu::uint(nz);
  s.f.axis = gpu::uint(axis);
  const bool gauss = p.kind == PassKind::Gaussian;
  const std::vector<float> no_weights;
  const std::vector<float>& kern = gauss ? in.fp.gaussians[plan.gi].kernel[std::size_t(axis)] : no_weights;
  if (gauss) {
    s.f.radius = gpu::uint(kern.size() / 2);
    s.f.w_offset = in.fp.w_offsets[plan.gi][std::size_t(axis)];
  } else {
    s.f.radius = gpu::uint(in.fp.closings[plan.ci][std::size_t(axis)]);
    s.f.mode = k < 3 ? ISOTOUCH_MORPH_MAX : ISOTOUCH_MORPH_MIN;
  }
  const bool x4 = impl.shaders == ShaderSet::Current && s.f.radius <= ISOTOUCH_DENSE_MAX_RADIUS;
  plan.info << (k ? ", " : ": ") << "xyz"[axis] << (p.kind == PassKind::Closing ? (k < 3 ? "max" : "min") : "")
            << " r=" << s.f.radius;
  SlabGeometry g;
  g.nz = std::uint64_t(nz);
  g.src_bytes_per_slice = in.slice_bytes;
  g.halo = axis == 2 ? s.f.radius : 0;
  g.dst_bytes_before = &floats_before;
  g.user = in.float_slice;
  g.wg_z = x4 ? 1 : ISOTOUCH_FILTER_WG_Z;
  auto sl = plan_slabs(in.ctx, g, in.bufs.field[plan.cur].handle(), in.bufs.field[1 - plan.cur].handle(), in.limit,
                       in.vol.path + ": " + p.label());
  if (!sl) throw VolumeError(sl.error);
  s.slabs = std::move(*sl.value);
  if (x4) {
    s.x4 = impl.filter_x4(in.vol.grid.dims, axis, int(s.f.radius), gauss ? 0u : s.f.mode, kern,
                          slabs_hold_quads(nx, s.slabs));
    s.pipe = s.x4;
  } else if (gauss) {
    if (!impl.gauss)
      impl.gauss = std::make_unique<ComputePipeline<gpu::Filter1dPush>>(in.ctx, gaussian1d_spv, 3, "gaussian1d");
    s.pipe = s.f1d = impl.gauss.get();
  } else {
    if (!impl.morph) impl.morph = std::make_unique<ComputePipeline<gpu::Filter1dPush>>(in.ctx, morph1d_spv, 2, "morph1d");
    s.pipe = s.f1d = impl.morph.get();
  }
  return s;
}

/// A Gaussian (3 axes) or a closing (6: max then min along each axis), one step per axis.
template <class ChainImpl>
void plan_separable(ChainImpl& impl, const ChainInput& in, const PassDesc& p, std::size_t i, ChainPlan& plan) {
  const int axes = p.kind == PassKind::Gaussian ? 3 : 6;
  for (int k = 0; k < axes; ++k) {
    plan.steps.push_back(plan_filter_axis(impl, in, p, i, k, plan));
    plan.cur = 1 - plan.cur;
  }
  if (p.kind == PassKind::Gaussian) {
    const auto& g = in.fp.gaussians[plan.gi];
    plan.info << " (sigma " << g.sigma_vox[0] << ", " << g.sigma_vox[1] << ", " << g.sigma_vox[2] << " voxels)";
    ++plan.gi;
  } else {
    ++plan.ci;
  }
}

/// The brick min/max over z-slabs that start on brick boundaries.
template <class ChainImpl>
void plan_minmax(ChainImpl& impl, const ChainInput& in, const PassDesc& p, std::size_t i, ChainPlan& plan) {
  ChainStep s;
  s.pass = i;
  s.type = ChainStep::MinMax;
  s.pipe = impl.minmax.get();
  SlabGeometry g;
  g.nz = std::uint64_t(in.vol.grid.dims[2]);
  g.src_bytes_per_slice = in.slice_bytes;
  g.halo = std::uint64_t(p.halo);
  g.z_multiple = ISOTOUCH_BRICK;
  g.dst_bytes_before = &bricks_before;
  g.user = in.layer;
  g.wg_z = in.legacy ? ISOTOUCH_MINMAX_WG_Z : 1;
  auto sl = plan_slabs(in.ctx, g, in.bufs.field[plan.cur].handle(), in.bufs.bricks.handle(), in.limit,
                       in.vol.path + ": " + p.label());
  if (!sl) throw VolumeError(sl.error);
  s.slabs = std::move(*sl.value);
  for (const Slab& b : s.slabs) {
    plan.rows_slices = std::max(plan.rows_slices, b.src_z1 - b.src_z0);
    if (!in.legacy) ++plan.extra_sets;
  }
  plan.info << ": " << in.bx << "x" << in.by << "x" << in.bz << " bricks";
  plan.steps.push_back(std::move(s));
}

/// Every dispatch of the run (z-slabs within the binding limit), pass by pass: planned before
/// anything is recorded, so that the descriptor arena is sized from the plan.
template <class ChainImpl>
void plan_chain(ChainImpl& impl, const std::vector<PassDesc>& passes, const ChainInput& in, ChainPlan& plan) {
  for (std::size_t i = 0; i < passes.size(); ++i) {
    const PassDesc& p = passes[i];
    plan.info << "  " << p.label();
    if (whole_field_gaussian(in, p, plan.gi)) {
      plan_gauss_axes(impl, in, i, plan);
    } else if (p.kind == PassKind::Gaussian || p.kind == PassKind::Closing) {
      plan_separable(impl, in, p, i, plan);
    } else if (whole_field_minmax(in, p)) {
      plan_whole_field_minmax(impl, in, i, plan);
    } else if (p.kind == PassKind::Gradient) {
      ChainStep s;
      s.pass = i;
      s.type = ChainStep::Gradient;
      s.slabs = impl.gradient->plan(in.vol.grid, in.bufs.field[plan.cur].handle(), in.bufs.samples.handle(),
                                    in.max_binding_bytes, in.vol.path);
      plan.steps.push_back(std::move(s));
    } else {
      plan_minmax(impl, in, p, i, plan);
    }
    std::size_t d = 0;
    for (const ChainStep& s : plan.steps)
      if (s.pass == i) d += s.slabs.size();
    plan.info << ", " << d << " dispatch(es)\n";
  }
}

/// The current set's brick min/max: the row ranges of one slab's source slices (2 floats per
/// brick column of every row, reused slab after slab) and its two pipelines. Null pipelines
/// without a brick min/max or with the legacy set.
template <class ChainImpl>
std::pair<const ComputePipeline<gpu::BrickMinMaxPush>*, const ComputePipeline<gpu::BrickMinMaxPush>*> minmax_rows(
    ChainImpl& impl, const std::vector<PassDesc>& passes, const BufferSource& buffer, const ChainInput& in,
    const ChainPlan& plan) {
  if (!has(passes, PassKind::BrickMinMax) || in.legacy || plan.rows_slices == 0)  // none, legacy or whole field
    return {nullptr, nullptr};
  const auto& lim = in.ctx.properties().limits;
  if (plan.rows_slices > lim.maxComputeWorkGroupCount[2])
    throw VolumeError(in.vol.path + ": " + std::to_string(plan.rows_slices) + " slices in one brick min/max slab exceed " +
                      "maxComputeWorkGroupCount[2] on " + in.ctx.info().name);
  const std::uint64_t rows_bytes = plan.rows_slices * std::uint64_t(in.vol.grid.dims[1]) * in.bx * 8;
  in.bufs.rows = buffer(rows_bytes, MemoryIntent::DeviceLocal, "brick row ranges");
  auto& pp = impl.minmax_x4[in.bx];
  if (!pp.first) {
    pp.first = std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(in.ctx, minmax_rows_spv, 2, "minmax_rows", 0u,
                                                                       std::vector<std::uint32_t>{in.bx}, 1u);
    pp.second = std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(in.ctx, minmax_bricks_spv, 2, "minmax_bricks",
                                                                        0u, std::vector<std::uint32_t>{in.bx}, 1u);
  }
  return {pp.first.get(), pp.second.get()};
}

/// Records the planned steps (uploads first where staging is used, a barrier after each
/// step, a timestamp after each pass, the readback copies last), submits and waits.
/// Returns the dispatches per pass; plan.cur ends on the field buffer the last filter wrote.
template <class ChainImpl>
std::vector<int> record_and_submit(ChainImpl& impl, const std::vector<PassDesc>& passes, const ChainInput& in,
                                   const SlabArgs& proto, DescriptorArena& arena, GpuTimer& timer, ChainPlan& plan,
                                   ChainOutput& out) {
  VulkanContext& ctx = in.ctx;
  ChainBuffers& b = in.bufs;
  const std::uint64_t n = in.n;
  VkCommandBuffer cmd = ctx.begin_commands();
  timer.record_reset(cmd);
  if (!in.direct) {
    record_copy(cmd, b.up, b.field[0], n * 4);
    if (b.w_up) record_copy(cmd, b.w_up, b.w_dev, in.fp.weights.size() * 4);
    barrier_transfer_to_compute(cmd);
  }
  timer.mark(cmd, 0);
  std::vector<int> dispatches(passes.size(), 0);
  plan.cur = 0;
  const std::vector<ChainStep>& steps = plan.steps;
  for (std::size_t k = 0; k < steps.size(); ++k) {
    const ChainStep& s = steps[k];
    SlabArgs args = proto;
    args.halo = passes[s.pass].halo;
    for (const Slab& sl : s.slabs) record_slab(cmd, arena, s, sl, args);
    if (s.type == ChainStep::Gradient) impl.gradient->record(cmd, arena, in.vol.grid, s.slabs);
    dispatches[s.pass] += int(s.slabs.size());
    if (s.type == ChainStep::Filter || s.type == ChainStep::GaussAxis) plan.cur = 1 - plan.cur;
    // The next step reads what this one wrote (and a filter overwrites what the previous
    // filter read): make this step's writes visible before any later dispatch.
    barrier_compute_to_compute(cmd);
    if (k + 1 == steps.size() || steps[k + 1].pass != s.pass) timer.mark(cmd, std::uint32_t(s.pass + 1));
  }
  if (in.direct) {
    barrier_compute_to_host(cmd);
  } else {
    barrier_compute_to_transfer(cmd);
    if (in.filters) record_copy(cmd, b.field[plan.cur], b.field_down, n * 4);
    if (b.samples) record_copy(cmd, b.samples, b.samples_down, n * sizeof(core::Sample));
    if (b.bricks) record_copy(cmd, b.bricks, b.bricks_down, std::uint64_t(in.bx) * in.by * in.bz * 2 * 4);
    barrier_transfer_to_host(cmd);
  }
  out.submit_wall_ms = ctx.submit_and_wait(cmd);
  return dispatches;
}

}  // namespace

ChainOutput PassChain::run_impl(const Volume& vol, std::uint64_t max_binding_bytes, InPlace* in_place) {
  VulkanContext& ctx = impl_->ctx;
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  std::uint64_t limit = ctx.max_binding_bytes();
  if (max_binding_bytes) limit = std::min<std::uint64_t>(limit, max_binding_bytes);
  check_dispatch_width(ctx, vol);
  const BufferSource buffer{ctx, impl_->kept, vol.path};
  const FilterParams fp = filter_params(vol, passes_);

  ChainBuffers bufs;
  const std::uint32_t bx = std::uint32_t((nx + 7) / 8), by = std::uint32_t((ny + 7) / 8),
                      bz = std::uint32_t((nz + 7) / 8);
  const std::uint64_t slice_bytes = std::uint64_t(nx) * std::uint64_t(ny) * 4;
  const BrickLayer layer{std::uint64_t(bx) * by * 2 * 4};
  ChainInput in{ctx, vol, fp, bufs, vol.grid.voxel_count(), slice_bytes, limit, max_binding_bytes, bx, by, bz,
                false, impl_->shaders == ShaderSet::Legacy,
                has(passes_, PassKind::Gaussian) || has(passes_, PassKind::Closing), &slice_bytes, &layer};
  make_buffers(buffer, passes_, impl_->gradient != nullptr, in);

  ChainPlan plan;
  plan_chain(*impl_, passes_, in, plan);
  if (plan.segments_bytes)
    bufs.segments = buffer(plan.segments_bytes, MemoryIntent::DeviceLocal, "brick slice segments");
  std::uint32_t sets = plan.extra_sets;
  for (const ChainStep& s : plan.steps) sets += std::uint32_t(s.slabs.size());
  const auto [mm_rows, mm_bricks] = minmax_rows(*impl_, passes_, buffer, in, plan);
  DescriptorArena arena(ctx, sets, 3 * sets);
  GpuTimer timer(ctx, std::uint32_t(passes_.size() + 1));

  ChainOutput out;
  auto t0 = std::chrono::steady_clock::now();
  std::memcpy(in.direct ? bufs.field[0].mapped() : bufs.up.mapped(), vol.voxels.data(), in.n * 4);
  if (bufs.w_dev) std::memcpy(in.direct ? bufs.w_dev.mapped() : bufs.w_up.mapped(), fp.weights.data(), fp.weights.size() * 4);
  out.upload_ms = ms_since(t0);
  const SlabArgs proto{nx, ny, nz, bx, by, mm_rows, mm_bricks, impl_->minmax.get(),
                       plan.mm_segments, plan.mm_slices, &bufs, &ctx.properties().limits, 0, vol.grid};
  const std::vector<int> dispatches = record_and_submit(*impl_, passes_, in, proto, arena, timer, plan, out);

  for (std::size_t i = 0; i < passes_.size(); ++i) {
    PassTiming pt;
    pt.label = passes_[i].label();
    pt.ms = timer.elapsed_ms(std::uint32_t(i), std::uint32_t(i + 1));
    pt.dispatches = dispatches[i];
    out.passes.push_back(pt);
  }
  out.gpu_timestamps = timer.enabled();

  t0 = std::chrono::steady_clock::now();
  read_outputs(vol, passes_, bufs, plan.cur, in.direct, in.filters, {bx, by, bz}, in_place, out);
  out.download_ms = ms_since(t0);
  impl_->last_run = plan.info.str();
  keep_buffers(bufs, impl_->kept);
  return out;
}

}  // namespace isotouch::engine
