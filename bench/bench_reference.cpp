// bench_reference.cpp - the standalone pass set. See bench_reference.h.
#include "isotouch/bench/bench_reference.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "isotouch/engine/cpu_filters.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/engine/vk_resources.h"
#include "isotouch/eval/stats.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/shaders/gauss_axis_x4_spv.h"
#include "isotouch/shaders/minmax_bricks_spv.h"
#include "isotouch/shaders/minmax_rows_spv.h"
#include "isotouch/shaders/minmax_segments_spv.h"
#include "isotouch/shaders/minmax_slices_spv.h"
#include "isotouch/shaders/gradient_whole_x4_spv.h"

namespace isotouch::bench {
using engine::BufferRange;
using engine::ComputePipeline;
using engine::GpuBuffer;

namespace {
std::uint32_t bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}
std::uint32_t groups(std::uint64_t n, std::uint32_t wg) { return std::uint32_t((n + wg - 1) / wg); }

// The rows of the set, in the order of the timestamps after them.
enum Row { kGauss, kGradient, kMinMaxRows, kMinMaxSegments, kRows };
const char* const kLabels[kRows] = {
    "gaussian: gauss_axis_x4 x, y, z (quads by texel fetch, vec4 store, 64x1x1)",
    "gradient: gradient_whole_x4 (quads + x neighbours by texel fetch, 64x1x1)",
    "brick_minmax: minmax_rows + minmax_bricks",
    "brick_minmax: minmax_segments + minmax_slices"};

bool same_floats(const float* a, const float* b, std::size_t n) { return std::memcmp(a, b, n * 4) == 0; }
}  // namespace

struct StandaloneSet::Impl {
  engine::VulkanContext& ctx;
  int nx, ny, nz;
  std::uint32_t bx, by, bz;
  std::uint64_t n;
  GpuBuffer in, a, b, samples, rows, segments, bricks_rows, bricks_segments;
  std::vector<std::unique_ptr<ComputePipeline<gpu::DensePush>>> gauss;  // x, y, z
  std::unique_ptr<ComputePipeline<gpu::DensePush>> gradient, segments_pipe;
  std::unique_ptr<ComputePipeline<gpu::BrickMinMaxPush>> rows_pipe, bricks_pipe, slices_pipe;
  std::vector<double> ms[kRows];  // per timed run; a brick min/max form's NaN where it ran untimed
  bool same[kRows] = {};
  int runs = 0;  // runs recorded, for the brick min/max forms' order

  explicit Impl(engine::VulkanContext& c) : ctx(c) {}
};

namespace {
void require(bool ok, const engine::Volume& v, const std::string& why) {
  if (!ok) throw engine::VolumeError(v.path + ": the standalone pass set does not run here: " + why);
}

GpuBuffer buffer(engine::VulkanContext& ctx, std::uint64_t bytes, const char* what) {
  return engine::make_buffer_or_throw(ctx, bytes, engine::MemoryIntent::DeviceLocal, what);
}

/// The brick min/max's push constants for the whole volume, halo 1.
gpu::BrickMinMaxPush minmax_push(int nx, int ny, int nz, std::uint32_t bx, std::uint32_t by, std::uint32_t bz) {
  gpu::BrickMinMaxPush pc{};
  pc.nx = gpu::uint(nx);
  pc.ny = gpu::uint(ny);
  pc.nz = gpu::uint(nz);
  pc.bx = bx;
  pc.by = by;
  pc.slab_bz = bz;
  pc.halo = 1;
  pc.pad0 = gpu::uint(nz);  // minmax_rows: the source slices in the binding
  return pc;
}
}  // namespace

StandaloneSet::StandaloneSet(engine::VulkanContext& ctx, const engine::Volume& v, double sigma_mm)
    : impl_(std::make_unique<Impl>(ctx)) {
  Impl& m = *impl_;
  m.nx = v.grid.dims[0];
  m.ny = v.grid.dims[1];
  m.nz = v.grid.dims[2];
  m.n = v.grid.voxel_count();
  m.bx = std::uint32_t((m.nx + 7) / 8);
  m.by = std::uint32_t((m.ny + 7) / 8);
  m.bz = std::uint32_t((m.nz + 7) / 8);
  const auto& lim = ctx.properties().limits;
  require(m.nx % 4 == 0 && m.nx >= 8 && m.ny >= 2 && m.nz >= 2, v, "rows of whole quads, nx >= 8, ny and nz >= 2");
  require(m.n * sizeof(core::Sample) <= ctx.max_binding_bytes() && m.n <= lim.maxTexelBufferElements, v,
          "the samples in one binding and the field in one texel view");
  require(ctx.device_local_is_host_visible(), v, "device-local memory is not host-visible");
  require(std::uint64_t(m.ny) <= lim.maxComputeWorkGroupCount[1] && std::uint64_t(m.nz) <= lim.maxComputeWorkGroupCount[2],
          v, "a dispatch per slice and row");
  const engine::GaussianAxes g = engine::gaussian_axes(v.grid, sigma_mm);
  for (int axis = 0; axis < 3; ++axis) {
    const std::vector<float>& k = g.kernel[std::size_t(axis)];
    require(k.size() <= 2 * ISOTOUCH_FUSED_MAX_RADIUS + 1, v, "a Gaussian radius above ISOTOUCH_FUSED_MAX_RADIUS");
    std::vector<std::uint32_t> spec = {std::uint32_t(m.nx), std::uint32_t(m.ny), std::uint32_t(m.nz),
                                       std::uint32_t(axis), std::uint32_t(k.size() / 2)};
    for (float w : k) spec.push_back(bits(w));
    spec.resize(5 + 2 * ISOTOUCH_FUSED_MAX_RADIUS + 1, 0u);
    m.gauss.push_back(std::make_unique<ComputePipeline<gpu::DensePush>>(ctx, gauss_axis_x4_spv, 2, "gauss_axis_x4",
                                                                        0u, spec, 1u));
    m.gauss.back()->set_texel_vec4(1u);
  }
  const engine::GradientConstants k = engine::gradient_constants(v.grid);
  m.gradient = std::make_unique<ComputePipeline<gpu::DensePush>>(
      ctx, gradient_whole_x4_spv, 3, "gradient_whole_x4", 0u,
      std::vector<std::uint32_t>{std::uint32_t(m.nx), std::uint32_t(m.ny), std::uint32_t(m.nz), bits(k.inv_2h[0]),
                                 bits(k.inv_2h[1]), bits(k.inv_2h[2]), bits(k.inv_h[0]), bits(k.inv_h[1]),
                                 bits(k.inv_h[2])},
      0b101u);
  m.gradient->set_texel_vec4(1u);
  const std::vector<std::uint32_t> dims = {std::uint32_t(m.nx), std::uint32_t(m.ny), std::uint32_t(m.nz)};
  m.segments_pipe =
      std::make_unique<ComputePipeline<gpu::DensePush>>(ctx, minmax_segments_spv, 3, "minmax_segments", 0u, dims, 0b101u);
  m.segments_pipe->set_texel_vec4(1u);
  m.rows_pipe = std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(ctx, minmax_rows_spv, 2, "minmax_rows", 0u,
                                                                         std::vector<std::uint32_t>{m.bx}, 1u);
  m.bricks_pipe = std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(ctx, minmax_bricks_spv, 2, "minmax_bricks",
                                                                           0u, std::vector<std::uint32_t>{m.bx}, 1u);
  m.slices_pipe = std::make_unique<ComputePipeline<gpu::BrickMinMaxPush>>(ctx, minmax_slices_spv, 2, "minmax_slices");
  m.in = buffer(ctx, m.n * 4, "voxels (standalone set)");
  m.a = buffer(ctx, m.n * 4, "field a (standalone set)");
  m.b = buffer(ctx, m.n * 4, "field b (standalone set)");
  m.samples = buffer(ctx, m.n * sizeof(core::Sample), "samples (standalone set)");
  m.rows = buffer(ctx, std::uint64_t(m.nz) * std::uint64_t(m.ny) * m.bx * 8, "brick row ranges (standalone set)");
  m.segments = buffer(ctx, std::uint64_t(m.nz) * m.by * m.bx * 8, "brick segments (standalone set)");
  const std::uint64_t brick_bytes = std::uint64_t(m.bx) * m.by * m.bz * 8;
  m.bricks_rows = buffer(ctx, brick_bytes, "brick ranges (standalone set, rows)");
  m.bricks_segments = buffer(ctx, brick_bytes, "brick ranges (standalone set, segments)");
  std::memcpy(m.in.mapped(), v.voxels.data(), m.n * 4);
}

StandaloneSet::~StandaloneSet() = default;

namespace {
BufferRange whole(const GpuBuffer& b) { return {b.handle(), 0, b.size()}; }
}  // namespace


// The brick min/max form timed in a run runs right after the gradient, as the chain's brick
// min/max does; the other runs between the Gaussian and the gradient, untimed (its output is
// still checked). The two swap each run: a form run right after the other form would find
// the field in the cache the other just read, which the chain's never does.
void StandaloneSet::run(bool timed) {
  Impl& m = *impl_;
  engine::VulkanContext& ctx = m.ctx;
  engine::DescriptorArena arena(ctx, 8, 24);
  engine::GpuTimer timer(ctx, 5);
  const std::uint32_t qx = std::uint32_t(m.nx / 4);
  const std::uint32_t gx = groups(qx, ISOTOUCH_DENSE_WG);
  const bool rows_timed = m.runs++ % 2 == 0;
  // One brick min/max form over m.a (rows: minmax_rows + minmax_bricks; else minmax_segments
  // + minmax_slices), a barrier after it.
  const auto record_minmax = [&](VkCommandBuffer cmd, bool rows) {
    const gpu::BrickMinMaxPush pc = minmax_push(m.nx, m.ny, m.nz, m.bx, m.by, m.bz);
    if (rows) {
      m.rows_pipe->bind(cmd, arena, {whole(m.a), whole(m.rows)});
      m.rows_pipe->push(cmd, pc);
      vkCmdDispatch(cmd, groups(std::uint64_t(m.bx) * std::uint64_t(m.ny), ISOTOUCH_DENSE_WG), 1, std::uint32_t(m.nz));
      engine::barrier_compute_to_compute(cmd);
      m.bricks_pipe->bind(cmd, arena, {whole(m.rows), whole(m.bricks_rows)});
      m.bricks_pipe->push(cmd, pc);
      vkCmdDispatch(cmd, groups(std::uint64_t(m.bx) * m.by, ISOTOUCH_DENSE_WG), 1, m.bz);
    } else {
      m.segments_pipe->bind(cmd, arena, {whole(m.a), whole(m.segments), whole(m.a)});
      vkCmdDispatch(cmd, groups(std::uint64_t(m.bx) * m.by, ISOTOUCH_DENSE_WG), 1, std::uint32_t(m.nz));
      engine::barrier_compute_to_compute(cmd);
      m.slices_pipe->bind(cmd, arena, {whole(m.segments), whole(m.bricks_segments)});
      m.slices_pipe->push(cmd, pc);
      vkCmdDispatch(cmd, groups(std::uint64_t(m.bx) * m.by, ISOTOUCH_DENSE_WG), 1, m.bz);
    }
    engine::barrier_compute_to_compute(cmd);
  };
  VkCommandBuffer cmd = ctx.begin_commands();
  timer.record_reset(cmd);
  timer.mark(cmd, 0);
  // Gaussian: in -> a (x), a -> b (y), b -> a (z).
  const GpuBuffer* io[3][2] = {{&m.in, &m.a}, {&m.a, &m.b}, {&m.b, &m.a}};
  for (int axis = 0; axis < 3; ++axis) {
    m.gauss[std::size_t(axis)]->bind(cmd, arena, {whole(*io[axis][0]), whole(*io[axis][1])});
    vkCmdDispatch(cmd, gx, std::uint32_t(m.ny), std::uint32_t(m.nz));
    engine::barrier_compute_to_compute(cmd);
  }
  timer.mark(cmd, 1);
  record_minmax(cmd, !rows_timed);  // the untimed form
  timer.mark(cmd, 2);
  m.gradient->bind(cmd, arena, {whole(m.a), whole(m.samples), whole(m.a)});
  vkCmdDispatch(cmd, gx, std::uint32_t(m.ny), std::uint32_t(m.nz));
  engine::barrier_compute_to_compute(cmd);
  timer.mark(cmd, 3);
  record_minmax(cmd, rows_timed);
  timer.mark(cmd, 4);
  engine::barrier_compute_to_host(cmd);
  (void)ctx.submit_and_wait(cmd);
  if (!timed) return;
  m.ms[kGauss].push_back(timer.elapsed_ms(0, 1));  // -1: no timestamps
  m.ms[kGradient].push_back(timer.elapsed_ms(2, 3));
  m.ms[rows_timed ? kMinMaxRows : kMinMaxSegments].push_back(timer.elapsed_ms(3, 4));
  m.ms[rows_timed ? kMinMaxSegments : kMinMaxRows].push_back(std::nan(""));  // not right after the gradient
}

void StandaloneSet::check(const engine::ChainOutput& cpu) {
  Impl& m = *impl_;
  const float* field = static_cast<const float*>(m.a.mapped());
  m.same[kGauss] = cpu.field && cpu.field->size() == m.n && same_floats(field, cpu.field->data(), m.n);
  m.same[kGradient] = cpu.samples && cpu.samples->samples.size() == m.n &&
                      std::memcmp(m.samples.mapped(), cpu.samples->samples.data(), m.n * sizeof(core::Sample)) == 0;
  auto same_bricks = [&](const GpuBuffer& b) {
    if (!cpu.bricks) return false;
    const float* f = static_cast<const float*>(b.mapped());
    const std::size_t count = cpu.bricks->min.size();
    if (count != std::size_t(m.bx) * m.by * m.bz) return false;
    for (std::size_t i = 0; i < count; ++i)
      if (std::memcmp(&f[2 * i], &cpu.bricks->min[i], 4) != 0 || std::memcmp(&f[2 * i + 1], &cpu.bricks->max[i], 4) != 0)
        return false;
    return true;
  };
  m.same[kMinMaxRows] = same_bricks(m.bricks_rows);
  m.same[kMinMaxSegments] = same_bricks(m.bricks_segments);
}

namespace {
/// The median of the finite values (-1: none, or a run without timestamps).
double finite_median(const std::vector<double>& v) {
  std::vector<double> f;
  for (double x : v)
    if (std::isfinite(x)) f.push_back(x);
  if (f.empty() || *std::min_element(f.begin(), f.end()) < 0) return -1.0;
  return eval::median(f);
}
}  // namespace

StandaloneFigures StandaloneSet::figures() const {
  const Impl& m = *impl_;
  StandaloneFigures f;
  f.all_same_bits = true;
  for (int r = 0; r < kRows; ++r) {
    StandaloneRow row;
    row.label = kLabels[r];
    row.ms = finite_median(m.ms[r]);
    row.same_bits = m.same[r];
    f.all_same_bits = f.all_same_bits && row.same_bits;
    f.rows.push_back(row);
  }
  const bool rows_faster = f.rows[kMinMaxRows].ms <= f.rows[kMinMaxSegments].ms;
  const StandaloneRow& mm = f.rows[rows_faster ? kMinMaxRows : kMinMaxSegments];
  f.best_minmax = mm.label;
  f.best_set_ms = f.rows[kGauss].ms + f.rows[kGradient].ms + mm.ms;
  const int best = rows_faster ? kMinMaxRows : kMinMaxSegments;
  for (std::size_t i = 0; i < m.ms[kGauss].size(); ++i)  // NaN in the runs the best form ran untimed
    f.set_ms_per_run.push_back(m.ms[kGauss][i] + m.ms[kGradient][i] + m.ms[best][i]);
  if (m.ms[0].empty()) f.why = "no run";
  return f;
}

}  // namespace isotouch::bench
