// sparse_chain.cpp - the sparse GPU engine: the chain's filters, gradient and brick min/max
// computed only on candidate bricks, published as a bricked core::SampleField. Three
// strategies (SparseChain::Strategy), the same bits:
//
// Lists (the default), one run: (host, hardware threads) the raw per-brick ranges taken while
// the voxels are copied into the input field; the candidates (sparse::select); one work list
// per filter op (sparse::make_work_list: the quads of the candidates' extents); (GPU, one
// command buffer) one filter_list_x4 dispatch per op and z-slab; (host) the candidates'
// exact ranges and the active ones' samples computed into the published pool.
// Dense: the dense chain over the whole volume, ranges and samples gathered on the host.
// PerBrick: (host) the voxels copied into per-slab staging buffers with the raw ranges;
// (GPU) staging -> device copies, one sparse_brick.comp dispatch per (slab, pool chunk),
// readback copies; (host) publish the active bricks. Every host step is timed in SparseOutput.
#include "isotouch/engine/sparse_chain.h"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <functional>
#include <iomanip>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/shaders/filter_list_x4_spv.h"
#include "isotouch/shaders/gauss_fused_list_spv.h"
#include "isotouch/shaders/sparse_brick_spv.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/parallel.h"
#include "isotouch/engine/passes.h"
#include "isotouch/engine/pool_recycler.h"
#include "isotouch/engine/vk_resources.h"

namespace isotouch::engine {

static_assert(sizeof(gpu::ListPush) == 32, "ListPush: 8 4-byte members (std430)");
static_assert(sizeof(gpu::SparseBrickPush) == 112, "SparseBrickPush: 28 4-byte members (std430)");
static_assert(int(sparse::OpKind::kGauss) == int(ISOTOUCH_SPARSE_OP_GAUSS) &&
                  int(sparse::OpKind::kMax) == int(ISOTOUCH_SPARSE_OP_MAX) &&
                  int(sparse::OpKind::kMin) == int(ISOTOUCH_SPARSE_OP_MIN),
              "op kinds shared with the shader");
static_assert(ISOTOUCH_SPARSE_SAMPLES == core::kBrickSamples, "9^3 stored samples");
static_assert(ISOTOUCH_SPARSE_WG == 8, "sparse::loop_trips_per_brick counts trips of a workgroup of 8");

namespace {
double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
constexpr std::uint64_t kSlotBytes = std::uint64_t(core::kBrickSamples) * sizeof(core::Sample);  // 11664
// Shared memory the shader declares: two ping-pong regions, two reduction arrays, a flag.
/// Workgroups per dispatch by default: lavapipe pays ~0.23 ms per workgroup, so few, but
/// enough to keep its threads busy to the end.
constexpr std::uint64_t kDefaultGroups = ISOTOUCH_SPARSE_DEFAULT_GROUPS;
constexpr std::uint64_t kSharedBytes = ISOTOUCH_SPARSE_SHARED_FLOATS * 4 + 2 * ISOTOUCH_SPARSE_WG * 4 + 4;

/// Floats the shader's shared buffers A and B need for `plan` (the largest box each one
/// receives, op 0 writing A, op 1 B, ...; interior bricks, whose boxes are not clipped).
std::pair<std::uint64_t, std::uint64_t> shared_sizes(const sparse::Plan& plan) {
  std::uint64_t a = 0, b = 0;
  int m[3] = {0, 0, 0};
  if (plan.ops.empty())
    a = std::uint64_t(plan.region[0]) * std::uint64_t(plan.region[1]) * std::uint64_t(plan.region[2]);
  for (std::size_t o = 0; o < plan.ops.size(); ++o) {
    m[plan.ops[o].axis] += plan.ops[o].radius;
    std::uint64_t box = 1;
    for (int k = 0; k < 3; ++k) box *= std::uint64_t(plan.region[std::size_t(k)] - 2 * m[k]);
    (o % 2 == 0 ? a : b) = std::max(o % 2 == 0 ? a : b, box);
  }
  return {a, b};
}

/// A z-range of brick layers, its raw slices and the candidates in it.
struct SlabPlan {
  int bz0 = 0, bz1 = 0;            ///< brick layers [bz0, bz1)
  int src_z0 = 0, src_z1 = 0;      ///< raw slices [src_z0, src_z1): layers + region apron
  std::size_t c0 = 0, c1 = 0;      ///< candidates [c0, c1)
  GpuBuffer staging, device;
};
struct Chunk {
  std::size_t slab = 0, c0 = 0, c1 = 0;  ///< candidates [c0, c1) of one slab, one pool buffer
  GpuBuffer pool, readback;
};

/// The host's part after the passes, on hardware_threads() threads: each candidate's
/// exact range over its brick + 1 voxel of the filtered field `f` (sparse::candidate_ranges,
/// the values of CandidateCpu::range) and the 9^3 samples of the active ones written straight into the
/// published pool: copied row by row from the dense-addressed samples `s`, or, with `s`
/// null, computed from `f` (sparse::brick_samples); beyond the grid the background with a
/// zero gradient. Sets out.publish_ms; `ranges_ms` the time of the ranges.
void finish_on_host(const Volume& vol, const sparse::Selection& sel, const float* f, const core::Sample* s,
                    const core::Isosurface& iso, float background, core::SampleFormat format, bool keep_input,
                    SparseOutput& out, double& ranges_ms, const std::shared_ptr<PoolRecycler>& recycler) {
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  const std::size_t slice = std::size_t(nx) * std::size_t(ny);
  const std::size_t nc = sel.candidates.size();
  const unsigned threads = threads_for(std::uint64_t(nc) * 1000u, hardware_threads());
  auto t0 = std::chrono::steady_clock::now();
  const auto nb = core::brick_counts(vol.grid);
  const std::vector<sparse::CandidateRange> ranges = sparse::candidate_ranges(vol.grid, f, sel.candidates, threads);
  ranges_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  const core::Sample outside{background, 0.0f, 0.0f, 0.0f};
  auto fill = [&](std::size_t c, core::Sample* o) {
    const auto b = core::brick_coords(sel.candidates[c], nb);
    if (!s) {
      sparse::brick_samples(vol.grid, f, b, background, o);
      return;
    }
    const int x0 = 8 * b[0], in_x = std::min(9, nx - x0);
    for (int k = 0; k < 9; ++k)
      for (int j = 0; j < 9; ++j) {
        core::Sample* d = o + 9 * j + 81 * k;
        const int y = 8 * b[1] + j, z = 8 * b[2] + k;
        int i = 0;
        if (y < ny && z < nz) {
          std::memcpy(d, s + std::size_t(z) * slice + std::size_t(y) * std::size_t(nx) + std::size_t(x0),
                      std::size_t(in_x) * sizeof(core::Sample));
          i = in_x;
        }
        for (; i < 9; ++i) d[i] = outside;
      }
  };
  sparse::publish_fill(vol.grid, sel, ranges, fill, threads, iso, background, format, keep_input, out, recycler);
  out.publish_ms = ms_since(t0);
}
/// The per-brick kernel's candidate ranges (vec4 records: lo, hi, NaN seen, its active
/// decision) read back, each checked: written by the shader, within llvmpipe's loop budget,
/// and the shader's decision the host's (sparse::is_active on the same range).
/// @throws std::logic_error naming the candidate and brick otherwise.
std::vector<sparse::CandidateRange> checked_ranges(const Volume& vol, const sparse::Selection& sel, const float* rf,
                                                   const core::Isosurface& iso, float background) {
  const std::size_t nc = sel.candidates.size();
  std::vector<sparse::CandidateRange> ranges(nc);
  for (std::size_t c = 0; c < nc; ++c) {
    const std::string at = vol.path + ": sparse chain: candidate " + std::to_string(c) + " (brick " +
                           std::to_string(sel.candidates[c]) + ")";
    if (rf[4 * c + 3] == 2.0f)
      throw std::logic_error(at + " ran out of llvmpipe's loop budget (65535 trips per invocation); "
                                  "sparse::loop_trips_per_brick underestimates sparse_brick.comp's loops");
    if (rf[4 * c + 3] != 0.0f && rf[4 * c + 3] != 1.0f) throw std::logic_error(at + " was never written by the shader");
    ranges[c] = {rf[4 * c], rf[4 * c + 1], rf[4 * c + 2] != 0.0f};
    float tile = 0;
    if (sparse::is_active(ranges[c], iso, background, tile) != (rf[4 * c + 3] != 0.0f))
      throw std::logic_error(at + ": shader and host disagree (range " + std::to_string(ranges[c].lo) + ".." +
                             std::to_string(ranges[c].hi) + ", tau " + std::to_string(iso.tau) + ")");
  }
  return ranges;
}
}  // namespace

/// The volume's voxels as the fused pass's input without a copy: their pages imported
/// (GpuBuffer::import_host) into `buf`, the range where the voxels lie in it. An empty
/// range (the caller copies) where import is not offered, the driver refuses, or the voxels
/// do not start on a quad the texel view can address (offset alignment).
static BufferRange import_voxels(VulkanContext& ctx, const Volume& vol, GpuBuffer& buf) {
  const VkDeviceSize bytes = VkDeviceSize(vol.grid.voxel_count()) * 4;
  if (ctx.host_import_alignment() == 0) return {};
  VkDeviceSize offset = 0;
  auto r = GpuBuffer::import_host(ctx, vol.voxels.data(), bytes, vol.path + ": voxels", offset);
  const VkDeviceSize texel_align = std::max<VkDeviceSize>(ctx.properties().limits.minTexelBufferOffsetAlignment, 16);
  if (!r || offset % texel_align != 0) return {};
  buf = std::move(*r.value);
  return {buf.handle(), offset, bytes};
}

/// Commands recorded around the list strategy's dispatches (copies and barriers).
using RecordFn = std::function<void(VkCommandBuffer)>;

/// One dispatch round of the list strategy: its pipeline, its z-slabs, its label.
struct ListStage {
  const ComputePipeline<gpu::ListPush>* pipe = nullptr;
  std::vector<Slab> slabs;
  std::string label;
  std::uint64_t invocations_per_unit = ISOTOUCH_LIST_INVOCATIONS;  ///< 1 for the fused pass's columns
};
/// The buffers a list run records into: the ping-pong fields (field 0 the input), the work
/// lists, and the staging / readback buffers where memory is not host-visible (else null).
struct ListBuffers {
  GpuBuffer* field[2] = {nullptr, nullptr};
  GpuBuffer *up = nullptr, *list_buf = nullptr, *list_up = nullptr, *field_down = nullptr;
  std::uint64_t list_bytes = 0;
  /// The fused pass's input where the volume's own voxels are imported (no copy; its
  /// buffer is null otherwise and field 0 holds the input).
  BufferRange imported{};
};

struct SparseChain::Impl {
  VulkanContext& ctx;
  std::vector<PassDesc> passes;
  /// sparse_brick.comp (the per-brick strategy), made on first use.
  std::unique_ptr<ComputePipeline<gpu::SparseBrickPush>> pipe;
  bool keep_input = false;
  std::uint32_t max_groups = 0;  ///< 0: kDefaultGroups
  std::string last_run;
  SparseChain::Strategy strategy = SparseChain::Strategy::Lists;
  std::unique_ptr<PassChain> dense;  ///< the dense strategy's chain (filters + gradient), made on first use
  /// The published pools' buffers, handed back when their snapshots die, for the next run.
  std::shared_ptr<PoolRecycler> pools = std::make_shared<PoolRecycler>();
  SparseOutput run_dense(const Volume& vol, const core::Isosurface& iso, float background, core::SampleFormat format,
                         std::uint64_t max_binding_bytes);
  /// The list strategy's steps: the fused Gaussian's stage, one filter op's stage, and the
  /// command buffer of all stages (device time per stage).
  ListStage fused_stage(const Volume& vol, const sparse::Plan& plan, const ListBuffers& b);
  ListStage filter_stage(const Volume& vol, const sparse::Plan& plan, std::size_t k, VkBuffer src, VkBuffer dst,
                         std::uint64_t limit);
  std::vector<double> record_lists(const Volume& vol, const std::vector<ListStage>& stages,
                                   const std::vector<sparse::WorkList>& lists, const std::vector<std::uint64_t>& base,
                                   const ListBuffers& b, bool direct, SparseOutput& out, int& dispatches,
                                   const RecordFn& before = {}, const RecordFn& after = {},
                                   DescriptorArena* keep_arena = nullptr, GpuTimer* keep_timer = nullptr);
  SparseOutput run_per_brick(const Volume& vol, const core::Isosurface& iso, float background,
                             core::SampleFormat format, std::uint64_t max_binding_bytes);
  SparseOutput run_lists(const Volume& vol, const core::Isosurface& iso, float background, core::SampleFormat format,
                         std::uint64_t max_binding_bytes);
  /// The list strategy's pipelines: filter_list_x4 by specialization (as PassChain's
  /// filter_x4), made on first use.
  std::map<std::vector<std::uint32_t>, std::unique_ptr<ComputePipeline<gpu::ListPush>>> filter_list;
  /// gauss_fused_list by specialization (size, radii, weights), made on first use.
  std::map<std::vector<std::uint32_t>, std::unique_ptr<ComputePipeline<gpu::ListPush>>> fused_pipes;
  /// The list strategy's buffers by name, kept from run to run (no new allocation and no
  /// first-touch page faults inside the timed dispatches when the sizes repeat).
  std::map<std::string, GpuBuffer> kept;
  GpuBuffer& kept_buffer(const std::string& name, std::uint64_t bytes, MemoryIntent intent, const std::string& path) {
    GpuBuffer& b = kept[name];
    if (!b || b.size() < bytes || b.intent() != intent) {
      b.reset();
      auto r = GpuBuffer::create(ctx, std::max<std::uint64_t>(bytes, 16), intent, name);
      if (!r) throw VolumeError(path + ": sparse chain: " + r.error);
      b = std::move(*r.value);
    }
    return b;
  }
  Impl(VulkanContext& c, std::vector<PassDesc> p)
      : ctx(c), passes(std::move(p)) {}
};

SparseChain::SparseChain(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SparseChain::~SparseChain() = default;
void SparseChain::set_keep_input(bool keep) { impl_->keep_input = keep; }
void SparseChain::set_max_workgroups(std::uint32_t groups) { impl_->max_groups = groups; }
void SparseChain::set_strategy(Strategy s) { impl_->strategy = s; }
std::uint64_t SparseChain::retained_pool_bytes() const { return impl_->pools->retained_bytes(); }
std::uint64_t SparseChain::recycled_pools() const { return impl_->pools->reuses(); }

SparseOutput SparseChain::Impl::run_dense(const Volume& vol, const core::Isosurface& iso, float background,
                                          core::SampleFormat format, std::uint64_t max_binding_bytes) {
  const auto t_total = std::chrono::steady_clock::now();
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];  // lambdas capture these (clang 14: not bindings)
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    throw VolumeError(vol.path + ": sparse chain: " + std::to_string(vol.voxels.size()) + " voxels for dims " +
                      std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz));
  const sparse::Plan plan = sparse::make_plan(vol.grid, passes, vol.path);
  if (!dense) {
    std::vector<PassDesc> list;
    for (const PassDesc& p : passes)
      if (p.kind != PassKind::BrickMinMax) list.push_back(p);
    auto r = PassChain::create(ctx, list, ShaderSet::Current);
    if (!r) throw VolumeError(vol.path + ": sparse chain: " + r.error);
    dense = std::move(*r.value);
  }
  SparseOutput out;
  // Host: raw brick ranges and the candidates.
  auto t0 = std::chrono::steady_clock::now();
  const sparse::Selection sel = sparse::select(vol.grid, vol.voxels.data(), plan, iso, hardware_threads());
  const double select_ms = ms_since(t0);

  // The dense passes, outputs read where they lie.
  t0 = std::chrono::steady_clock::now();
  PassChain::InPlace at;
  const ChainOutput d = dense->run_in_place(vol, at, max_binding_bytes);
  const double dense_wall_ms = ms_since(t0);
  const float* f = at.field ? at.field : vol.voxels.data();
  const core::Sample* s = at.samples;
  if (!s) throw std::logic_error(vol.path + ": sparse chain: the dense chain returned no samples");

  double ranges_ms = 0;
  finish_on_host(vol, sel, f, s, iso, background, format, keep_input, out, ranges_ms, pools);
  const double gather_ms = ranges_ms;
  out.passes.push_back({"candidate selection (host)", select_ms, 0});
  int dispatches = 0, slabs = 0;
  for (const PassTiming& p : d.passes) {
    out.passes.push_back({p.label + " (GPU, dense)", p.ms, p.dispatches});
    dispatches += p.dispatches;
    slabs = p.dispatches;  // the gradient, last: one dispatch per z-slab
  }
  out.passes.push_back({"dense chain wall (upload, submit, in-place outputs)", dense_wall_ms, 0});
  out.passes.push_back({"candidate ranges (host)", gather_ms, 0});
  out.passes.push_back({"publish: active samples gathered into the pool (host)", out.publish_ms, 0});
  out.upload_ms = d.upload_ms;
  out.submit_wall_ms = d.submit_wall_ms;
  out.download_ms = d.download_ms;
  out.stats.slabs = std::size_t(slabs);
  out.stats.dispatches = std::size_t(dispatches);
  out.total_ms = ms_since(t_total);
  std::ostringstream info;
  const auto nb = core::brick_counts(vol.grid);
  info << "strategy: dense x4 passes over the volume, candidates gathered on the host; " << nb[0] << "x" << nb[1]
       << "x" << nb[2] << " = " << out.stats.bricks_total << " bricks, " << out.stats.candidates << " candidates, "
       << out.stats.active << " active; " << dispatches << " dispatch(es); snapshot " << out.stats.snapshot_bytes
       << " B vs dense fp32 " << out.stats.dense_fp32_bytes << " B";
  last_run = info.str();
  return out;
}

ListStage SparseChain::Impl::fused_stage(const Volume& vol, const sparse::Plan& plan, const ListBuffers& b) {
  const std::uint64_t n = vol.grid.voxel_count();
  std::array<std::vector<float>, 3> kernels;
  for (std::size_t a = 0; a < 3; ++a) {
    const sparse::Op& op = plan.ops[a];
    kernels[a].assign(plan.weights.begin() + op.w_offset, plan.weights.begin() + op.w_offset + 2 * op.radius + 1);
  }
  std::vector<std::uint32_t> spec = fused_gaussian_spec(vol.grid.dims, kernels);
  spec.push_back(sparse::fused_pairs(plan) ? 1u : 0u);  // constant_id 33: PAIRS (the list's form)
  auto& p = fused_pipes[spec];
  if (!p) {
    p = std::make_unique<ComputePipeline<gpu::ListPush>>(ctx, gauss_fused_list_spv, 3, "gauss_fused_list", 0u, spec,
                                                         0b101u);
    p->set_texel_vec4(1u);
  }
  ListStage st;
  st.pipe = p.get();
  st.invocations_per_unit = 1;
  st.label = "gaussian x r=" + std::to_string(plan.ops[0].radius) + " + y r=" + std::to_string(plan.ops[1].radius) +
             " + z r=" + std::to_string(plan.ops[2].radius) + " fused" + (sparse::fused_pairs(plan) ? ", slices paired" : "");
  Slab whole;
  whole.nz = std::uint64_t(vol.grid.dims[2]);
  whole.src_z1 = whole.nz;
  whole.src = b.imported.buffer ? b.imported : BufferRange{b.field[0]->handle(), 0, n * 4};
  whole.dst = {b.field[1]->handle(), 0, n * 4};
  st.slabs.push_back(whole);
  return st;
}

ListStage SparseChain::Impl::filter_stage(const Volume& vol, const sparse::Plan& plan, std::size_t k, VkBuffer src,
                                          VkBuffer dst, std::uint64_t limit) {
  const sparse::Op& op = plan.ops[k];
  ListStage st;
  st.label = std::string(op.kind == sparse::OpKind::kGauss ? "gaussian" : op.kind == sparse::OpKind::kMax ? "max" : "min") +
             " " + "xyz"[op.axis] + " r=" + std::to_string(op.radius);
  const std::uint64_t slice_bytes = std::uint64_t(vol.grid.dims[0]) * std::uint64_t(vol.grid.dims[1]) * 4;
  SlabGeometry g;
  g.nz = std::uint64_t(vol.grid.dims[2]);
  g.src_bytes_per_slice = slice_bytes;
  g.dst_bytes_before = +[](std::uint64_t z, const void* u) { return z * *static_cast<const std::uint64_t*>(u); };
  g.halo = op.axis == 2 ? std::uint64_t(op.radius) : 0;
  g.user = &slice_bytes;
  auto sl = plan_slabs(ctx, g, src, dst, limit, vol.path + ": " + st.label);
  if (!sl) throw VolumeError(sl.error);
  st.slabs = std::move(*sl.value);
  std::vector<std::uint32_t> spec(6 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 2, 0u);
  for (int a = 0; a < 3; ++a) spec[std::size_t(a)] = std::uint32_t(vol.grid.dims[std::size_t(a)]);
  spec[3] = std::uint32_t(op.axis);
  spec[4] = std::uint32_t(op.radius);
  if (op.kind == sparse::OpKind::kGauss)
    std::memcpy(&spec[5], plan.weights.data() + op.w_offset, std::size_t(2 * op.radius + 1) * 4);
  spec[5 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 1] = std::uint32_t(op.kind);  // constant_id 38: the mode
  const bool quads = slabs_hold_quads(vol.grid.dims[0], st.slabs);
  spec[5 + 2 * ISOTOUCH_DENSE_MAX_RADIUS + 2] = quads ? 1u : 0u;  // constant_id 39: quad input
  auto& p = filter_list[spec];
  if (!p) {
    p = std::make_unique<ComputePipeline<gpu::ListPush>>(ctx, filter_list_x4_spv, 3, "filter_list_x4", 0u, spec,
                                                         0b101u);
    if (quads) p->set_texel_vec4(1u);
  }
  st.pipe = p.get();
  return st;
}

std::vector<double> SparseChain::Impl::record_lists(const Volume& vol, const std::vector<ListStage>& stages,
                                                    const std::vector<sparse::WorkList>& lists,
                                                    const std::vector<std::uint64_t>& base, const ListBuffers& b,
                                                    bool direct, SparseOutput& out, int& dispatches,
                                                    const RecordFn& before, const RecordFn& after,
                                                    DescriptorArena* keep_arena, GpuTimer* keep_timer) {
  const auto& lim = ctx.properties().limits;
  const std::size_t K = stages.size();
  const std::uint64_t n = vol.grid.voxel_count();
  const int nx = vol.grid.dims[0];
  std::uint32_t sets = 0;
  for (const ListStage& st : stages) sets += std::uint32_t(st.slabs.size());
  // The caller's arena and timer where given (reset here: the previous submission has
  // completed), else this recording's own.
  std::optional<DescriptorArena> own_arena;
  std::optional<GpuTimer> own_timer;
  if (keep_arena) keep_arena->reset();
  else own_arena.emplace(ctx, std::max<std::uint32_t>(sets, 1), 3 * std::max<std::uint32_t>(sets, 1));
  if (!keep_timer) own_timer.emplace(ctx, std::uint32_t(K + 1));
  DescriptorArena& arena = keep_arena ? *keep_arena : *own_arena;
  GpuTimer& timer = keep_timer ? *keep_timer : *own_timer;
  VkCommandBuffer cmd = ctx.begin_commands();
  timer.record_reset(cmd);
  if (before) {
    before(cmd);
  } else if (!direct) {
    record_copy(cmd, *b.up, *b.field[0], n * 4);
    record_copy(cmd, *b.list_up, *b.list_buf, b.list_bytes);
    barrier_transfer_to_compute(cmd);
  }
  timer.mark(cmd, 0);
  const BufferRange list_range{b.list_buf->handle(), 0, b.list_bytes};
  for (std::size_t k = 0; k < K; ++k) {
    const sparse::WorkList& w = lists[k];
    for (const Slab& sl : stages[k].slabs) {
      // A slab's units are those of its slices (the lists are sorted by z).
      const std::uint64_t u0 = w.z_first[sl.z0], u1 = w.z_first[sl.z0 + sl.nz];
      if (u1 == u0) continue;
      const std::uint64_t invocations = (u1 - u0) * stages[k].invocations_per_unit;
      const std::uint64_t groups = (invocations + ISOTOUCH_DENSE_WG - 1) / ISOTOUCH_DENSE_WG;
      const std::uint64_t gx = std::min<std::uint64_t>(groups, lim.maxComputeWorkGroupCount[0]);
      const std::uint64_t gy = (groups + gx - 1) / gx;
      if (gy > lim.maxComputeWorkGroupCount[1])
        throw VolumeError(vol.path + ": sparse chain: " + std::to_string(groups) + " workgroups exceed one dispatch on " +
                          ctx.info().name);
      gpu::ListPush pc{};
      pc.z0 = gpu::uint(sl.z0);
      pc.src_z0 = gpu::uint(sl.src_z0);
      pc.src_offset = gpu::uint(sl.src_offset_elems);
      pc.dst_offset = gpu::uint(sl.dst_offset_elems);
      pc.unit0 = gpu::uint(base[k] + u0);
      pc.units = gpu::uint(u1 - u0);
      pc.groups_x = gpu::uint(gx);
      pc.vec4_out = (nx % ISOTOUCH_DENSE_VOXELS == 0 && sl.dst_offset_elems % ISOTOUCH_DENSE_VOXELS == 0) ? 1u : 0u;
      stages[k].pipe->bind(cmd, arena, {sl.src, sl.dst, list_range});
      stages[k].pipe->push(cmd, pc);
      vkCmdDispatch(cmd, std::uint32_t(gx), std::uint32_t(gy), 1);
      ++dispatches;
    }
    // The next op reads what this one wrote, and overwrites what this one read.
    barrier_compute_to_compute(cmd);
    timer.mark(cmd, std::uint32_t(k + 1));
  }
  if (after) {
    after(cmd);
  } else if (direct) {
    barrier_compute_to_host(cmd);
  } else {
    barrier_compute_to_transfer(cmd);
    record_copy(cmd, *b.field[K % 2], *b.field_down, n * 4);
    barrier_transfer_to_host(cmd);
  }
  out.submit_wall_ms = ctx.submit_and_wait(cmd);
  std::vector<double> ms(K, 0.0);
  for (std::size_t k = 0; k < K; ++k) ms[k] = timer.elapsed_ms(std::uint32_t(k), std::uint32_t(k + 1));
  return ms;
}

SparseOutput SparseChain::Impl::run_lists(const Volume& vol, const core::Isosurface& iso, float background,
                                          core::SampleFormat format, std::uint64_t max_binding_bytes) {
  const auto t_total = std::chrono::steady_clock::now();
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    throw VolumeError(vol.path + ": sparse chain: " + std::to_string(vol.voxels.size()) + " voxels for dims " +
                      std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz));
  const sparse::Plan plan = sparse::make_plan(vol.grid, passes, vol.path);
  for (const sparse::Op& op : plan.ops)
    if (op.radius > int(ISOTOUCH_DENSE_MAX_RADIUS)) {
      // filter_x4 unrolls at most ISOTOUCH_DENSE_MAX_RADIUS taps a side; the dense chain
      // takes the 1-D shaders for wider kernels.
      SparseOutput out = run_dense(vol, iso, background, format, max_binding_bytes);
      last_run = "strategy lists: a filter of radius " + std::to_string(op.radius) + " > " +
                 std::to_string(ISOTOUCH_DENSE_MAX_RADIUS) + " ran as dense; " + last_run;
      return out;
    }
  const auto& lim = ctx.properties().limits;
  std::uint64_t limit = ctx.max_binding_bytes();
  if (max_binding_bytes) limit = std::min<std::uint64_t>(limit, max_binding_bytes);
  const bool direct = ctx.device_local_is_host_visible();
  SparseOutput out;
  const std::uint64_t n = vol.grid.voxel_count();
  const bool filters = !plan.ops.empty();
  // One Gaussian whose field fits one binding and one texel view runs as ONE fused pass
  // (gauss_fused_list.comp) over columns of the last extent's quads; other chains run one
  // pass per op over its extent's quads.
  const bool fused = sparse::fusable(plan, vol.grid) && n * 4 <= limit && n / 4 <= lim.maxTexelBufferElements;
  const std::size_t K = fused ? 1 : plan.ops.size();  // stages (dispatch rounds)

  // Host, on hardware_threads() threads: the candidates, and the voxels copied into the
  // input field (or its staging buffer) where a filter runs, in the same pass over them -
  // unless the fused pass reads the volume's own voxels, imported (no copy).
  auto t0 = std::chrono::steady_clock::now();
  GpuBuffer imported;
  const BufferRange in_range = fused && direct ? import_voxels(ctx, vol, imported) : BufferRange{};
  GpuBuffer* field0 = filters && !in_range.buffer
                          ? &kept_buffer("lists: field 0", n * 4, MemoryIntent::DeviceLocal, vol.path)
                          : nullptr;
  GpuBuffer* up =
      field0 && !direct ? &kept_buffer("lists: voxels staging", n * 4, MemoryIntent::Upload, vol.path) : nullptr;
  float* input = !field0 ? nullptr : static_cast<float*>(direct ? field0->mapped() : up->mapped());
  const sparse::Selection sel = sparse::select(vol.grid, vol.voxels.data(), plan, iso, hardware_threads(), input);
  const double select_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  const std::vector<sparse::Extent> ext = sparse::list_extents(plan);
  std::vector<sparse::WorkList> lists;
  std::vector<std::uint64_t> base;  // first unit of each list in the list buffer
  std::uint64_t total_units = 0;
  for (std::size_t k = 0; k < K; ++k) {
    // The column list on one thread below 2^24 voxels (256^3): on a shared machine a
    // second thread's start waits for a core (chest at -500 HU, load 2.6: 0.90 / 3.32 ms
    // min / median on two threads against 0.81 / 0.83 on one); a 512^3 list takes 30 ms.
    lists.push_back(fused ? sparse::make_column_list(vol.grid, sel.candidates, ext.back(), vol.path,
                                                     sparse::fused_pairs(plan), threads_for(n / 16, hardware_threads()))
                          : sparse::make_work_list(vol.grid, sel.candidates, ext[k], vol.path));
    base.push_back(total_units);
    total_units += lists.back().unit_count();
  }
  const double lists_ms = ms_since(t0);

  // Buffers: two dense-addressed fields (ping-pong; the input is field 0) and the work
  // lists; staging and readback only where device-local memory is not host-visible.
  t0 = std::chrono::steady_clock::now();
  const std::uint64_t list_bytes = std::max<std::uint64_t>(total_units, 1) * 8;
  if (list_bytes / 4 > lim.maxTexelBufferElements)
    throw VolumeError(vol.path + ": sparse chain: " + std::to_string(list_bytes / 4) +
                      " work-list texels exceed maxTexelBufferElements " + std::to_string(lim.maxTexelBufferElements) +
                      " on " + ctx.info().name);
  GpuBuffer* field[2] = {field0, K ? &kept_buffer("lists: field 1", n * 4, MemoryIntent::DeviceLocal, vol.path) : nullptr};
  GpuBuffer* list_buf = K ? &kept_buffer("lists: work lists", list_bytes, MemoryIntent::DeviceLocal, vol.path) : nullptr;
  GpuBuffer *list_up = nullptr, *field_down = nullptr;
  if (!direct && K) {
    list_up = &kept_buffer("lists: work lists staging", list_bytes, MemoryIntent::Upload, vol.path);
    field_down = &kept_buffer("lists: field readback", n * 4, MemoryIntent::Readback, vol.path);
  }
  if (K) {
    char* dst = static_cast<char*>(direct ? list_buf->mapped() : list_up->mapped());
    for (std::size_t k = 0; k < K; ++k) std::memcpy(dst + base[k] * 8, lists[k].units.data(), lists[k].units.size() * 4);
  }
  out.upload_ms = ms_since(t0);

  // Stages: the fused pass, or one per op (op k reads field k % 2 and writes the other);
  // then one command buffer of their dispatches.
  const ListBuffers bufs{{field[0], field[1]}, up, list_buf, list_up, field_down, list_bytes, in_range};
  std::vector<ListStage> stages;
  for (std::size_t k = 0; k < K; ++k)
    stages.push_back(fused ? fused_stage(vol, plan, bufs)
                           : filter_stage(vol, plan, k, field[k % 2]->handle(), field[1 - k % 2]->handle(), limit));
  int dispatches = 0;
  const std::vector<double> stage_ms =
      K ? record_lists(vol, stages, lists, base, bufs, direct, out, dispatches) : std::vector<double>{};

  // Host: ranges and samples from the last filter's output where it lies (the raw voxels
  // without a filter).
  const float* f = !K ? vol.voxels.data()
                      : static_cast<const float*>(direct ? field[K % 2]->mapped() : field_down->mapped());
  double ranges_ms = 0;
  finish_on_host(vol, sel, f, nullptr, iso, background, format, keep_input, out, ranges_ms, pools);

  out.passes.push_back({std::string("candidate selection: raw ranges over the bricks' windows") +
                            (input ? " + the input copy" : in_range.buffer ? " (input imported, no copy)" : "") +
                            " (host)",
                        select_ms, 0});
  out.passes.push_back({"work lists + their upload (host)", lists_ms + out.upload_ms, 0});
  std::ostringstream info;
  const auto nb = core::brick_counts(vol.grid);
  info << "strategy: lists; " << nb[0] << "x" << nb[1] << "x" << nb[2] << " = " << out.stats.bricks_total
       << " bricks, " << out.stats.candidates << " candidates, " << out.stats.active << " active; quads per filter:";
  for (std::size_t k = 0; k < K; ++k) {
    const double pct = 100.0 * double(lists[k].quads) * ISOTOUCH_DENSE_VOXELS / double(n);
    std::ostringstream lab;
    lab.precision(3);
    lab << stages[k].label << " on " << pct << " % of the voxels (GPU)";
    out.passes.push_back({lab.str(), stage_ms[k], 0});
    info << " " << stages[k].label << " " << lists[k].quads;
  }
  out.passes.push_back({"candidate ranges (host)", ranges_ms, 0});
  out.passes.push_back({"publish: active samples computed into the pool (host)", out.publish_ms, 0});
  out.stats.dispatches = std::size_t(dispatches);
  out.stats.slabs = K ? stages.back().slabs.size() : 0;
  out.total_ms = ms_since(t_total);
  info << "; " << dispatches << " dispatch(es), " << total_units << " units; snapshot " << out.stats.snapshot_bytes
       << " B vs dense fp32 " << out.stats.dense_fp32_bytes << " B";
  last_run = info.str();
  return out;
}

Result<std::unique_ptr<SparseChain>> SparseChain::create(VulkanContext& ctx, std::vector<PassDesc> passes) {
  using R = Result<std::unique_ptr<SparseChain>>;
  if (std::string e = sparse::validate(passes); !e.empty()) return R::fail("sparse chain: " + e);
  const auto& lim = ctx.properties().limits;
  if (lim.maxComputeSharedMemorySize < kSharedBytes)
    return R::fail("sparse chain: sparse_brick.comp needs " + std::to_string(kSharedBytes) +
                   " bytes of shared memory, " + ctx.info().name + " offers " +
                   std::to_string(lim.maxComputeSharedMemorySize));
  if (lim.maxComputeWorkGroupInvocations < ISOTOUCH_SPARSE_WG || lim.maxComputeWorkGroupSize[0] < ISOTOUCH_SPARSE_WG)
    return R::fail("sparse chain: workgroup of " + std::to_string(ISOTOUCH_SPARSE_WG) + " invocations too large for " +
                   ctx.info().name);
  // The shader synchronises with subgroupBarrier(): the workgroup must be one subgroup.
  VkPhysicalDeviceSubgroupProperties sub{};
  sub.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES;
  VkPhysicalDeviceProperties2 p2{};
  p2.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2;
  p2.pNext = &sub;
  vkGetPhysicalDeviceProperties2(ctx.physical_device(), &p2);
  if (sub.subgroupSize < ISOTOUCH_SPARSE_WG || !(sub.supportedStages & VK_SHADER_STAGE_COMPUTE_BIT) ||
      !(sub.supportedOperations & VK_SUBGROUP_FEATURE_BASIC_BIT))
    return R::fail("sparse chain: sparse_brick.comp needs a compute subgroup of at least " +
                   std::to_string(ISOTOUCH_SPARSE_WG) + " invocations with basic operations; " + ctx.info().name +
                   " has subgroupSize " + std::to_string(sub.subgroupSize));
  return R::ok(std::unique_ptr<SparseChain>(new SparseChain(std::make_unique<Impl>(ctx, std::move(passes)))));
}

std::string SparseChain::describe() const {
  std::ostringstream s;
  s << "sparse chain, passes:";
  for (std::size_t i = 0; i < impl_->passes.size(); ++i) s << (i ? " -> " : " ") << impl_->passes[i].label();
  s << " (brick_minmax halo 1 implied)";
  if (impl_->strategy == Strategy::Lists) {
    s << "\nstrategy: lists - filter_list_x4 (the dense filters' x4 code) on the quads of the candidate bricks "
         "dilated by the rest of the stencil, each quad once per pass; dense-addressed buffers read in place; "
         "per candidate its exact range and the active ones' 9^3 samples computed on the host straight into the "
         "published pool";
    s << "\nleft out (not created, not run): sparse_brick (per-brick strategy); the dense passes filter_x4, "
         "gaussian1d, morph1d, gradient_x4, gradient, brick_minmax (a filter wider than "
      << ISOTOUCH_DENSE_MAX_RADIUS << " voxels a side runs the dense strategy)";
    if (!impl_->last_run.empty()) s << "\nlast run: " << impl_->last_run;
    return s.str();
  }
  if (impl_->strategy == Strategy::Dense) {
    s << "\nstrategy: dense - the dense chain's x4 passes (filters + gradient, current shaders) over the whole "
         "volume, outputs read in place; per candidate its exact range and the 9^3 samples of the active ones "
         "gathered on the host";
    s << "\nleft out (not created, not run): sparse_brick (per-brick strategy), gaussian1d, morph1d, gradient, "
         "brick_minmax (legacy dense passes)";
    if (impl_->dense) s << "\ndense chain: " << impl_->dense->describe();
    if (!impl_->last_run.empty()) s << "\nlast run: " << impl_->last_run;
    return s.str();
  }
  s << "\nstrategy: per-brick";
  s << "\npipelines created: sparse_brick (one workgroup of " << ISOTOUCH_SPARSE_WG
    << " per candidate brick: raw region -> filters -> min/max -> value+gradient of active bricks)";
  s << "\nleft out (not created, not run): gaussian1d, morph1d, gradient, brick_minmax (the dense passes)";
  s << "\nbuffers per run: raw voxels per z-slab of brick layers (device-local + staging), candidate ids"
       " (+ staging), ops + weights (+ staging), candidate ranges (vec4 + readback), brick pool per chunk"
       " (729 vec4 per candidate, device-local + readback)";
  s << "\nleft out buffers: ping-pong field, dense samples (16 B/voxel), dense brick ranges";
  if (!impl_->last_run.empty()) s << "\nlast run: " << impl_->last_run;
  return s.str();
}

SparseOutput SparseChain::run(const Volume& vol, const core::Isosurface& iso, float background,
                              core::SampleFormat format, std::uint64_t max_binding_bytes) {
  switch (impl_->strategy) {
    case Strategy::Lists: return impl_->run_lists(vol, iso, background, format, max_binding_bytes);
    case Strategy::Dense: return impl_->run_dense(vol, iso, background, format, max_binding_bytes);
    case Strategy::PerBrick: break;
  }
  return impl_->run_per_brick(vol, iso, background, format, max_binding_bytes);
}

namespace {

/// The per-brick shader holds the plan's filters in its shared memory and op table, or the
/// scene needs the dense chain (the message says so).
void check_per_brick_plan(const Volume& vol, const sparse::Plan& plan) {
  const auto [shared_a, shared_b] = shared_sizes(plan);
  if (shared_a + shared_b > ISOTOUCH_SPARSE_SHARED_FLOATS || plan.ops.size() > ISOTOUCH_SPARSE_MAX_OPS)
    throw VolumeError(vol.path + ": sparse chain: filters of total radius " + std::to_string(plan.radius[0]) + "," +
                      std::to_string(plan.radius[1]) + "," + std::to_string(plan.radius[2]) +
                      " voxels need " + std::to_string(shared_a + shared_b) + " floats of shared memory (" +
                      std::to_string(plan.ops.size()) + " ops); the sparse shader holds " +
                      std::to_string(ISOTOUCH_SPARSE_SHARED_FLOATS) + " floats and " +
                      std::to_string(ISOTOUCH_SPARSE_MAX_OPS) + " ops: use the dense chain");
}

/// A new buffer of at least 16 bytes, or a VolumeError naming the volume.
struct PerBrickBuffer {
  VulkanContext& ctx;
  const std::string& path;
  GpuBuffer operator()(std::uint64_t bytes, MemoryIntent intent, const std::string& what) const {
    auto r = GpuBuffer::create(ctx, std::max<std::uint64_t>(bytes, 16), intent, what);
    if (!r) throw VolumeError(path + ": sparse chain: " + r.error);
    return std::move(*r.value);
  }
};

/// Slabs of brick layers whose raw slices (plus the region's apron) fit one binding.
std::vector<SlabPlan> per_brick_slabs(const VulkanContext& ctx, const Volume& vol, const sparse::Plan& plan,
                                      std::uint64_t buf_limit) {
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  const auto nb = core::brick_counts(vol.grid);
  const std::uint64_t slice = std::uint64_t(nx) * std::uint64_t(ny);
  const int below = 1 + plan.radius[2], above = 2 + plan.radius[2];
  auto src_range = [&](int bz0, int bz1) {
    return std::pair{std::max(8 * bz0 - below, 0), std::min(8 * bz1 + above, nz)};
  };
  std::vector<SlabPlan> slabs;
  for (int bz = 0; bz < nb[2];) {
    int end = bz + 1;
    auto bytes = [&](int e) {
      const auto [a, b] = src_range(bz, e);
      return std::uint64_t(b - a) * slice * 4;
    };
    if (bytes(end) > buf_limit)
      throw VolumeError(vol.path + ": sparse chain: one brick layer of " + std::to_string(nx) + "x" +
                        std::to_string(ny) + " voxels (+ " + std::to_string(below + above) +
                        " apron slices) needs " + std::to_string(bytes(end)) + " bytes, more than a binding of " +
                        std::to_string(buf_limit) + " bytes on " + ctx.info().name);
    while (end < nb[2] && bytes(end + 1) <= buf_limit) ++end;
    SlabPlan s;
    s.bz0 = bz;
    s.bz1 = end;
    std::tie(s.src_z0, s.src_z1) = src_range(bz, end);
    slabs.push_back(std::move(s));
    bz = end;
  }
  return slabs;
}

/// Each slab's raw slices: a staging and a device-local buffer, the staging ones filled in
/// one pass over the voxels. Returns the allocation and the copy wall times [ms].
std::pair<double, double> stage_slabs(const Volume& vol, const PerBrickBuffer& buffer, std::vector<SlabPlan>& slabs) {
  const std::uint64_t slice = std::uint64_t(vol.grid.dims[0]) * std::uint64_t(vol.grid.dims[1]);
  auto t0 = std::chrono::steady_clock::now();
  for (SlabPlan& s : slabs) {
    const std::uint64_t bytes = std::uint64_t(s.src_z1 - s.src_z0) * slice * 4;
    s.staging = buffer(bytes, MemoryIntent::Upload, "raw voxels staging (slab)");
    s.device = buffer(bytes, MemoryIntent::DeviceLocal, "raw voxels (slab)");
  }
  const double alloc_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  for (int z = 0; z < vol.grid.dims[2]; ++z) {
    const float* src = vol.voxels.data() + std::size_t(z) * slice;
    for (SlabPlan& s : slabs)
      if (z >= s.src_z0 && z < s.src_z1)
        std::memcpy(static_cast<char*>(s.staging.mapped()) + std::uint64_t(z - s.src_z0) * slice * 4, src, slice * 4);
  }
  return {alloc_ms, ms_since(t0)};
}

/// Candidates per slab (ascending ids: contiguous), pool chunks within each slab, each chunk
/// within a binding and a dispatch's workgroup count.
std::vector<Chunk> per_brick_chunks(const VulkanContext& ctx, const Volume& vol, const sparse::Selection& sel,
                                    std::uint64_t buf_limit, const PerBrickBuffer& buffer, std::vector<SlabPlan>& slabs) {
  const auto nb = core::brick_counts(vol.grid);
  const std::size_t nc = sel.candidates.size();
  const std::uint64_t layer = std::uint64_t(nb[0]) * std::uint64_t(nb[1]);
  const std::size_t max_chunk = std::size_t(
      std::min<std::uint64_t>(buf_limit / kSlotBytes, ctx.properties().limits.maxComputeWorkGroupCount[0]));
  if (max_chunk == 0)
    throw VolumeError(vol.path + ": sparse chain: one brick pool slot of " + std::to_string(kSlotBytes) +
                      " bytes exceeds a binding of " + std::to_string(buf_limit) + " bytes");
  if (std::uint64_t(std::max<std::size_t>(nc, 1)) * 16 > buf_limit)
    throw VolumeError(vol.path + ": sparse chain: " + std::to_string(nc) + " candidate ranges exceed a binding of " +
                      std::to_string(buf_limit) + " bytes");
  std::vector<Chunk> chunks;
  std::size_t c = 0;
  for (std::size_t si = 0; si < slabs.size(); ++si) {
    SlabPlan& s = slabs[si];
    s.c0 = c;
    while (c < nc && sel.candidates[c] < std::uint64_t(s.bz1) * layer) ++c;
    s.c1 = c;
    for (std::size_t a = s.c0; a < s.c1; a += max_chunk) {
      Chunk ch;
      ch.slab = si;
      ch.c0 = a;
      ch.c1 = std::min(s.c1, a + max_chunk);
      const std::uint64_t bytes = std::uint64_t(ch.c1 - ch.c0) * kSlotBytes;
      ch.pool = buffer(bytes, MemoryIntent::DeviceLocal, "brick pool (chunk)");
      ch.readback = buffer(bytes, MemoryIntent::Readback, "brick pool readback (chunk)");
      chunks.push_back(std::move(ch));
    }
  }
  return chunks;
}

/// The shader's parameter buffer: 4 words per op (axis, radius, kind, weights' offset) for
/// ISOTOUCH_SPARSE_MAX_OPS ops, then the weights.
std::vector<std::uint32_t> per_brick_params(const sparse::Plan& plan) {
  std::vector<std::uint32_t> params(4 * ISOTOUCH_SPARSE_MAX_OPS + plan.weights.size(), 0);
  for (std::size_t i = 0; i < plan.ops.size(); ++i) {
    const sparse::Op& o = plan.ops[i];
    params[4 * i] = std::uint32_t(o.axis);
    params[4 * i + 1] = std::uint32_t(o.radius);
    params[4 * i + 2] = std::uint32_t(o.kind);
    params[4 * i + 3] = o.w_offset;
  }
  std::memcpy(params.data() + 4 * ISOTOUCH_SPARSE_MAX_OPS, plan.weights.data(), plan.weights.size() * 4);
  return params;
}

/// The push constants every chunk's dispatch shares (the chunk's own fields left 0).
gpu::SparseBrickPush per_brick_push(const Volume& vol, const sparse::Plan& plan, const core::Isosurface& iso,
                                    float background) {
  const auto nb = core::brick_counts(vol.grid);
  const GradientConstants k = gradient_constants(vol.grid);
  gpu::SparseBrickPush pc{};
  pc.nx = gpu::uint(vol.grid.dims[0]);
  pc.ny = gpu::uint(vol.grid.dims[1]);
  pc.nz = gpu::uint(vol.grid.dims[2]);
  pc.bx = gpu::uint(nb[0]);
  pc.by = gpu::uint(nb[1]);
  pc.sx = gpu::uint(plan.region[0]);
  pc.sy = gpu::uint(plan.region[1]);
  pc.sz = gpu::uint(plan.region[2]);
  pc.rx = gpu::uint(plan.radius[0]);
  pc.ry = gpu::uint(plan.radius[1]);
  pc.rz = gpu::uint(plan.radius[2]);
  pc.n_ops = gpu::uint(plan.ops.size());
  pc.inside_above = iso.inside == core::InsideIs::kAbove ? 1u : 0u;
  pc.threshold = sparse::threshold(iso);
  pc.background = background;
  pc.buf_b = gpu::uint(shared_sizes(plan).first);
  set_inverse_spacings(pc, k);
  return pc;
}

/// The buffers of the parameters, the candidate ids and the candidate ranges.
struct PerBrickIo {
  GpuBuffer params_up, params_dev, cand_up, cand_dev, ranges_dev, ranges_down;
};

/// The shader's inputs and outputs besides the slabs and chunks, the inputs written.
PerBrickIo per_brick_io(const PerBrickBuffer& buffer, const sparse::Plan& plan, const sparse::Selection& sel) {
  const std::size_t nc = sel.candidates.size();
  const std::vector<std::uint32_t> params = per_brick_params(plan);
  PerBrickIo io{buffer(params.size() * 4, MemoryIntent::Upload, "sparse params staging"),
                buffer(params.size() * 4, MemoryIntent::DeviceLocal, "sparse params"),
                buffer(nc * 4, MemoryIntent::Upload, "candidate ids staging"),
                buffer(nc * 4, MemoryIntent::DeviceLocal, "candidate ids"),
                buffer(nc * 16, MemoryIntent::DeviceLocal, "candidate ranges"),
                buffer(nc * 16, MemoryIntent::Readback, "candidate ranges readback")};
  std::memcpy(io.params_up.mapped(), params.data(), params.size() * 4);
  if (nc) std::memcpy(io.cand_up.mapped(), sel.candidates.data(), nc * 4);
  return io;
}

/// One command buffer: the uploads, one dispatch per chunk, the readbacks; submitted and
/// waited for. `workgroups(n)`: the workgroups of a dispatch of n candidates.
template <class Workgroups>
void record_per_brick(VulkanContext& ctx, const ComputePipeline<gpu::SparseBrickPush>& pipe,
                      const std::vector<SlabPlan>& slabs, const std::vector<Chunk>& chunks, const PerBrickIo& io,
                      std::size_t nc, gpu::SparseBrickPush pc, const Workgroups& workgroups, GpuTimer& timer,
                      SparseOutput& out) {
  DescriptorArena arena(ctx, std::uint32_t(std::max<std::size_t>(chunks.size(), 1)),
                        5 * std::uint32_t(std::max<std::size_t>(chunks.size(), 1)));
  VkCommandBuffer cmd = ctx.begin_commands();
  timer.record_reset(cmd);
  for (const SlabPlan& s : slabs) record_copy(cmd, s.staging, s.device, s.staging.size());
  record_copy(cmd, io.params_up, io.params_dev, io.params_up.size());
  if (nc) record_copy(cmd, io.cand_up, io.cand_dev, nc * 4);
  // Every range record starts as NaN: a record the shader never wrote (a skipped or cut
  // workgroup on any driver) has no 0/1 decision in .w and is refused below.
  if (nc) vkCmdFillBuffer(cmd, io.ranges_dev.handle(), 0, nc * 16, 0x7fc00000u);
  barrier_transfer_to_compute(cmd);
  timer.mark(cmd, 0);
  for (const Chunk& ch : chunks) {
    const SlabPlan& s = slabs[ch.slab];
    pc.src_z0 = gpu::uint(s.src_z0);
    pc.src_offset = 0;
    pc.cand_offset = gpu::uint(ch.c0);
    pc.pool_base = gpu::uint(ch.c0);
    pc.cand_end = gpu::uint(ch.c1);
    pc.groups = gpu::uint(workgroups(ch.c1 - ch.c0));
    out.stats.workgroups += pc.groups;
    pipe.bind(cmd, arena,
              {BufferRange{s.device.handle(), 0, s.device.size()}, BufferRange{io.cand_dev.handle(), 0, io.cand_dev.size()},
               BufferRange{io.params_dev.handle(), 0, io.params_dev.size()},
               BufferRange{io.ranges_dev.handle(), 0, io.ranges_dev.size()},
               BufferRange{ch.pool.handle(), 0, ch.pool.size()}});
    pipe.push(cmd, pc);
    vkCmdDispatch(cmd, pc.groups, 1, 1);
  }
  barrier_compute_to_transfer(cmd);
  timer.mark(cmd, 1);
  if (nc) record_copy(cmd, io.ranges_dev, io.ranges_down, nc * 16);
  for (const Chunk& ch : chunks) record_copy(cmd, ch.pool, ch.readback, ch.pool.size());
  barrier_transfer_to_host(cmd);
  timer.mark(cmd, 2);
  out.submit_wall_ms = ctx.submit_and_wait(cmd);
}

/// describe()'s "last run" line of a per-brick run.
std::string per_brick_info(const Volume& vol, const sparse::Plan& plan, std::size_t slabs, std::size_t chunks,
                           std::uint64_t per_group, const SparseOutput& out) {
  const auto nb = core::brick_counts(vol.grid);
  std::ostringstream info;
  info << nb[0] << "x" << nb[1] << "x" << nb[2] << " = " << out.stats.bricks_total << " bricks, " << out.stats.candidates
       << " candidates, " << out.stats.active << " active; region " << plan.region[0] << "x" << plan.region[1] << "x"
       << plan.region[2] << " (radius " << plan.radius[0] << "," << plan.radius[1] << "," << plan.radius[2]
       << "; ops: " << plan.text << "), " << slabs << " slab(s), " << chunks << " dispatch(es), " << out.stats.workgroups
       << " workgroups (<= " << per_group << " bricks each: " << sparse::loop_trips_per_brick(plan)
       << " loop trips per brick); snapshot "
       << out.stats.snapshot_bytes << " B vs dense fp32 " << out.stats.dense_fp32_bytes << " B";
  return info.str();
}

}  // namespace

SparseOutput SparseChain::Impl::run_per_brick(const Volume& vol, const core::Isosurface& iso, float background,
                                              core::SampleFormat format, std::uint64_t max_binding_bytes) {
  const auto t_total = std::chrono::steady_clock::now();
  const int nx = vol.grid.dims[0], ny = vol.grid.dims[1], nz = vol.grid.dims[2];
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    throw VolumeError(vol.path + ": sparse chain: " + std::to_string(vol.voxels.size()) + " voxels for dims " +
                      std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz));
  const sparse::Plan plan = sparse::make_plan(vol.grid, passes, vol.path);
  check_per_brick_plan(vol, plan);
  std::uint64_t limit = ctx.max_binding_bytes();
  if (max_binding_bytes) limit = std::min<std::uint64_t>(limit, max_binding_bytes);
  const std::uint64_t alloc_limit = ctx.max_allocation_bytes() ? ctx.max_allocation_bytes() : limit;
  const std::uint64_t buf_limit = std::min(limit, alloc_limit);
  const PerBrickBuffer buffer{ctx, vol.path};
  std::vector<SlabPlan> slabs = per_brick_slabs(ctx, vol, plan, buf_limit);

  // Host: staging copies, then the candidates (raw brick ranges in one pass over the voxels).
  SparseOutput out;
  const auto [alloc_ms, staging_ms] = stage_slabs(vol, buffer, slabs);
  auto t0 = std::chrono::steady_clock::now();
  const sparse::Selection sel = sparse::select(vol.grid, vol.voxels.data(), plan, iso);
  const std::size_t nc = sel.candidates.size();
  const double select_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  const std::vector<Chunk> chunks = per_brick_chunks(ctx, vol, sel, buf_limit, buffer, slabs);
  const PerBrickIo io = per_brick_io(buffer, plan, sel);
  out.upload_ms = staging_ms + (alloc_ms + ms_since(t0));

  // Workgroups of a dispatch of n candidates: the preferred count, but never so few that a
  // workgroup loops over more bricks than llvmpipe's loop budget allows (its loops would
  // silently stop), never more than one per candidate.
  const std::uint64_t per_group = sparse::max_bricks_per_workgroup(plan);
  const std::uint64_t preferred = max_groups ? max_groups : kDefaultGroups;
  auto workgroups = [&](std::uint64_t n) {
    const std::uint64_t needed = (n + per_group - 1) / per_group;
    return std::min<std::uint64_t>(std::max(preferred, needed), n);
  };
  GpuTimer timer(ctx, 3);
  if (!pipe) pipe = std::make_unique<ComputePipeline<gpu::SparseBrickPush>>(ctx, sparse_brick_spv, 5, "sparse_brick");
  record_per_brick(ctx, *pipe, slabs, chunks, io, nc, per_brick_push(vol, plan, iso, background), workgroups, timer,
                   out);

  // Host: ranges, the shader's decision checked against the host's, publication.
  t0 = std::chrono::steady_clock::now();
  const std::vector<sparse::CandidateRange> ranges =
      checked_ranges(vol, sel, static_cast<const float*>(io.ranges_down.mapped()), iso, background);
  std::vector<const core::Sample*> where(nc, nullptr);
  for (const Chunk& ch : chunks)
    for (std::size_t c = ch.c0; c < ch.c1; ++c)
      where[c] = static_cast<const core::Sample*>(ch.readback.mapped()) + (c - ch.c0) * core::kBrickSamples;
  out.download_ms = ms_since(t0);
  t0 = std::chrono::steady_clock::now();
  sparse::publish(vol.grid, sel, ranges, [&](std::size_t c) { return where[c]; }, iso, background, format,
                  keep_input, out, pools);
  out.publish_ms = ms_since(t0);

  const double gpu_ms = timer.elapsed_ms(0, 1), copy_ms = timer.elapsed_ms(1, 2);
  out.passes.push_back({"staging copies (host)", staging_ms, 0});
  out.passes.push_back({"candidate selection (host)", select_ms, 0});
  out.passes.push_back({plan.text + " + gradient + min/max on candidates (GPU)", gpu_ms, int(chunks.size())});
  out.passes.push_back({"readback copies (GPU)", copy_ms, 0});
  out.stats.slabs = slabs.size();
  out.stats.dispatches = chunks.size();
  out.total_ms = ms_since(t_total);
  last_run = per_brick_info(vol, plan, slabs.size(), chunks.size(), per_group, out);
  return out;
}

// ---- SparseFilter: the list strategy's filter stage on chosen candidates -----------------

struct SparseFilter::Impl {
  std::unique_ptr<SparseChain::Impl> chain;  ///< the list strategy's pipelines and kept buffers
  Volume meta;                               ///< grid and path (no voxels)
  sparse::Plan plan;
  std::vector<sparse::Extent> ext;
  bool fused = false, direct = false;
  std::uint64_t limit = 0;
  GpuBuffer input;                ///< the resident copy of the volume (op 0's source)
  GpuBuffer out[2];               ///< op k writes out[k % 2] (the fused pass: out[0])
  GpuBuffer staging, readback;    ///< where device memory is not host-visible
  int up_z0 = 0, up_z1 = 0;       ///< staging slices [up_z0, up_z1) not yet uploaded
  std::string last;
  /// Kept from run to run (their creation cost about 0.1 ms a run on lavapipe): made by the
  /// first run, sized for its stages' slabs (the same every run: they depend on the grid).
  std::unique_ptr<DescriptorArena> arena;
  std::unique_ptr<GpuTimer> timer;

  std::size_t stages() const { return fused ? 1 : plan.ops.size(); }
  std::uint64_t slice_floats() const { return std::uint64_t(meta.grid.dims[0]) * std::uint64_t(meta.grid.dims[1]); }
};

SparseFilter::SparseFilter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SparseFilter::~SparseFilter() = default;

Result<std::unique_ptr<SparseFilter>> SparseFilter::create(VulkanContext& ctx, const Volume& vol,
                                                           const std::vector<PassDesc>& passes, bool staging) {
  using R = Result<std::unique_ptr<SparseFilter>>;
  if (std::string e = sparse::validate(passes); !e.empty()) return R::fail("sparse filter: " + e);
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    return R::fail(vol.path + ": sparse filter: " + std::to_string(vol.voxels.size()) + " voxels for the grid");
  auto m = std::make_unique<Impl>();
  m->meta.grid = vol.grid;
  m->meta.path = vol.path;
  try {
    m->plan = sparse::make_plan(vol.grid, passes, vol.path);
  } catch (const std::exception& e) {
    return R::fail(e.what());
  }
  if (m->plan.ops.empty()) return R::fail("sparse filter: no filter in the pass list (the gradient needs no GPU pass)");
  for (const sparse::Op& op : m->plan.ops)
    if (op.radius > int(ISOTOUCH_DENSE_MAX_RADIUS))
      return R::fail("sparse filter: a filter of radius " + std::to_string(op.radius) + " > " +
                     std::to_string(ISOTOUCH_DENSE_MAX_RADIUS) + " (the list kernels' widest)");
  const auto& lim = ctx.properties().limits;
  const std::uint64_t n = vol.grid.voxel_count();
  m->limit = ctx.max_binding_bytes();
  m->direct = ctx.device_local_is_host_visible() && !staging;
  m->fused = sparse::fusable(m->plan, vol.grid) && n * 4 <= m->limit && n / 4 <= lim.maxTexelBufferElements;
  m->ext = sparse::list_extents(m->plan);
  m->chain = std::make_unique<SparseChain::Impl>(ctx, passes);
  auto make = [&](GpuBuffer& b, MemoryIntent intent, const char* what) {
    auto r = GpuBuffer::create(ctx, n * 4, intent, vol.path + ": sparse filter: " + what);
    if (!r) return r.error;
    b = std::move(*r.value);
    return std::string();
  };
  std::string err = make(m->input, MemoryIntent::DeviceLocal, "input");
  if (err.empty()) err = make(m->out[0], MemoryIntent::DeviceLocal, "output A");
  if (err.empty() && m->stages() > 1) err = make(m->out[1], MemoryIntent::DeviceLocal, "output B");
  if (err.empty() && !m->direct) err = make(m->staging, MemoryIntent::Upload, "input staging");
  if (err.empty() && !m->direct) err = make(m->readback, MemoryIntent::Readback, "output readback");
  if (!err.empty()) return R::fail(err);
  std::memcpy(m->direct ? m->input.mapped() : m->staging.mapped(), vol.voxels.data(), std::size_t(n) * 4);
  m->up_z1 = m->direct ? 0 : vol.grid.dims[2];
  std::unique_ptr<SparseFilter> f(new SparseFilter(std::move(m)));
  try {
    (void)f->filter({});  // the pipelines, and the first upload
  } catch (const std::exception& e) {
    return R::fail(e.what());
  }
  return R::ok(std::move(f));
}

void SparseFilter::set_bricks(const float* voxels, const std::vector<std::uint32_t>& bricks) noexcept {
  Impl& m = *impl_;
  const core::Grid& g = m.meta.grid;
  const auto nb = core::brick_counts(g);
  const int nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  float* dst = static_cast<float*>(m.direct ? m.input.mapped() : m.staging.mapped());
  for (std::uint32_t id : bricks) {
    const auto b = core::brick_coords(id, nb);
    const int x0 = 8 * b[0], w = std::min(x0 + 8, nx) - x0, z0 = 8 * b[2], z1 = std::min(z0 + 8, nz);
    for (int z = z0; z < z1; ++z)
      for (int y = 8 * b[1]; y < std::min(8 * b[1] + 8, ny); ++y) {
        const std::size_t row = (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(nx) + std::size_t(x0);
        std::memcpy(dst + row, voxels + row, std::size_t(w) * 4);
      }
    if (!m.direct) {
      m.up_z0 = m.up_z1 > m.up_z0 ? std::min(m.up_z0, z0) : z0;
      m.up_z1 = std::max(m.up_z1, z1);
    }
  }
}

SparseFilter::Output SparseFilter::filter(const std::vector<std::uint32_t>& candidates) {
  Impl& m = *impl_;
  SparseChain::Impl& c = *m.chain;
  const Volume& vol = m.meta;
  const std::size_t K = m.stages();
  const std::uint64_t n = vol.grid.voxel_count();
  Output o;
  auto t0 = std::chrono::steady_clock::now();
  std::vector<sparse::WorkList> lists;
  std::vector<std::uint64_t> base;
  std::uint64_t total_units = 0;
  for (std::size_t k = 0; k < K; ++k) {
    lists.push_back(m.fused ? sparse::make_column_list(vol.grid, candidates, m.ext.back(), vol.path,
                                                       sparse::fused_pairs(m.plan), 1)
                            : sparse::make_work_list(vol.grid, candidates, m.ext[k], vol.path));
    base.push_back(total_units);
    total_units += lists.back().unit_count();
    o.quads += lists.back().quads;
  }
  const std::uint64_t list_bytes = std::max<std::uint64_t>(total_units, 1) * 8;
  if (list_bytes / 4 > c.ctx.properties().limits.maxTexelBufferElements)
    throw VolumeError(vol.path + ": sparse filter: " + std::to_string(list_bytes / 4) +
                      " work-list texels exceed maxTexelBufferElements on " + c.ctx.info().name);
  GpuBuffer* list_buf = &c.kept_buffer("filter: work lists", list_bytes, MemoryIntent::DeviceLocal, vol.path);
  GpuBuffer* list_up =
      m.direct ? nullptr : &c.kept_buffer("filter: work lists staging", list_bytes, MemoryIntent::Upload, vol.path);
  char* dst = static_cast<char*>(m.direct ? list_buf->mapped() : list_up->mapped());
  for (std::size_t k = 0; k < K; ++k) std::memcpy(dst + base[k] * 8, lists[k].units.data(), lists[k].units.size() * 4);
  o.lists_ms = ms_since(t0);

  // Stages: the fused pass reads the resident input and writes out[0]; else op k reads the
  // input (k = 0) or out[(k - 1) % 2] and writes out[k % 2].
  ListBuffers b;
  b.field[1] = &m.out[0];
  b.list_buf = list_buf;
  b.list_bytes = list_bytes;
  b.imported = {m.input.handle(), 0, n * 4};
  std::vector<ListStage> stages;
  for (std::size_t k = 0; k < K; ++k)
    stages.push_back(m.fused ? c.fused_stage(vol, m.plan, b)
                             : c.filter_stage(vol, m.plan, k, k == 0 ? m.input.handle() : m.out[(k - 1) % 2].handle(),
                                              m.out[k % 2].handle(), m.limit));
  GpuBuffer& result = m.out[m.fused ? 0 : (K - 1) % 2];

  // Copies where device memory is not host-visible: the staged slices up, the lists up, and
  // back the slices the host reads (8 b - 1 .. 8 b + 9 of every candidate).
  const std::uint64_t slice_bytes = m.slice_floats() * 4;
  int read_z0 = vol.grid.dims[2], read_z1 = 0;
  const auto nb = core::brick_counts(vol.grid);
  for (std::uint32_t id : candidates) {
    const int bz = int(core::brick_coords(id, nb)[2]);
    read_z0 = std::min(read_z0, std::max(8 * bz - 1, 0));
    read_z1 = std::max(read_z1, std::min(8 * bz + 10, vol.grid.dims[2]));
  }
  const RecordFn before = [&](VkCommandBuffer cmd) {
    if (m.direct) return;
    if (m.up_z1 > m.up_z0) {
      const VkBufferCopy r{std::uint64_t(m.up_z0) * slice_bytes, std::uint64_t(m.up_z0) * slice_bytes,
                           std::uint64_t(m.up_z1 - m.up_z0) * slice_bytes};
      vkCmdCopyBuffer(cmd, m.staging.handle(), m.input.handle(), 1, &r);
    }
    record_copy(cmd, *list_up, *list_buf, list_bytes);
    barrier_transfer_to_compute(cmd);
  };
  const RecordFn after = [&](VkCommandBuffer cmd) {
    if (m.direct) {
      barrier_compute_to_host(cmd);
      return;
    }
    barrier_compute_to_transfer(cmd);
    if (read_z1 > read_z0) {
      const VkBufferCopy r{std::uint64_t(read_z0) * slice_bytes, std::uint64_t(read_z0) * slice_bytes,
                           std::uint64_t(read_z1 - read_z0) * slice_bytes};
      vkCmdCopyBuffer(cmd, result.handle(), m.readback.handle(), 1, &r);
    }
    barrier_transfer_to_host(cmd);
  };
  if (!m.arena) {
    std::uint32_t sets = 0;
    for (const ListStage& st : stages) sets += std::uint32_t(st.slabs.size());
    sets = std::max<std::uint32_t>(sets, 1);
    m.arena = std::make_unique<DescriptorArena>(c.ctx, sets, 3 * sets);
    m.timer = std::make_unique<GpuTimer>(c.ctx, std::uint32_t(K + 1));
  }
  SparseOutput timing;
  int dispatches = 0;
  (void)c.record_lists(vol, stages, lists, base, b, m.direct, timing, dispatches, before, after, m.arena.get(),
                       m.timer.get());
  m.up_z0 = m.up_z1 = 0;
  o.submit_wall_ms = timing.submit_wall_ms;
  o.dispatches = std::size_t(dispatches);
  o.field = static_cast<const float*>(m.direct ? result.mapped() : m.readback.mapped());
  std::ostringstream info;
  info << candidates.size() << " candidates, " << o.quads << " quads, " << dispatches << " dispatch(es)";
  m.last = info.str();
  return o;
}

std::string SparseFilter::describe() const {
  const Impl& m = *impl_;
  std::ostringstream s;
  s << "sparse filter (the list strategy's filter stage on chosen candidates): " << m.plan.text << "; "
    << (m.fused ? "gauss_fused_list (x, y, z fused)" : "filter_list_x4, one pass per op")
    << " on the quads of the candidates' extents; the volume resident on the device, patched brick by brick"
    << (m.direct ? " (host-visible device memory: written in place, output read in place)"
                 : " (through a staging copy; the slices read back)");
  const std::uint64_t bytes = m.input.size() + m.out[0].size() + m.out[1].size() + m.staging.size() + m.readback.size();
  s << "; " << std::fixed << std::setprecision(1) << double(bytes) / (1024.0 * 1024.0)
    << " MiB of buffers held for it (volume copy, outputs" << (m.direct ? ")" : ", staging, readback)");
  if (!m.last.empty()) s << "; last run: " << m.last;
  return s.str();
}

}  // namespace isotouch::engine
