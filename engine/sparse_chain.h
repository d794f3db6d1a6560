// sparse_chain.h - the sparse GPU engine: passes computed only on the
// bricks whose value range can straddle the isovalue, published as a bricked SampleField
// (core/brick_field.h). This header is the contract that
// bench engine (bench/bench_engine.cpp) and the scene runner (run/engine_run.cpp) code
// against; the owner may add members but keeps these names and meanings.
#pragma once
#include "isotouch/engine/core_names.h"
#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "isotouch/core/brick_field.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/result.h"

namespace isotouch::engine {

class VulkanContext;
class PoolRecycler;

/// What a sparse run found and published.
struct SparseStats {
  std::size_t bricks_total = 0;      ///< ceil(dims/8) product
  std::size_t candidates = 0;        ///< bricks computed (raw range, widened by the stencils, straddles tau)
  std::size_t active = 0;            ///< bricks published with samples (smoothed range, halo 1, straddles tau)
  std::uint64_t snapshot_bytes = 0;  ///< bytes of the published snapshot (table + tiles + pool)
  std::uint64_t dense_fp32_bytes = 0;  ///< voxels * 16: the dense fp32 snapshot it replaces
  std::size_t slabs = 0;       ///< GPU: z-slabs of brick layers (bindings <= the limit); CPU: 0
  std::size_t dispatches = 0;  ///< GPU: dispatches (one per slab and pool chunk); CPU: 0
  std::size_t workgroups = 0;  ///< GPU: workgroups over all dispatches (each loops over its bricks); CPU: 0
};

/// One sparse run. `field` is a bricked core::SampleField (empty dense samples).
struct SparseOutput {
  core::SampleField field;
  SparseStats stats;
  std::vector<PassTiming> passes;  ///< per stage (e.g. "raw minmax", "gaussian+gradient on candidates")
  double upload_ms = 0;            ///< host work before submit (staging copies)
  double submit_wall_ms = 0;       ///< submit to fence, wall clock (all submits)
  double download_ms = 0;          ///< readback copies
  double publish_ms = 0;           ///< building the bricked SampleField on the host
  double total_ms = 0;             ///< wall clock of run(), everything included
  /// What was handed to core::make_bricked_field (kept only with keep_input; the field
  /// owns the pool otherwise). Tests read it.
  core::BrickedInput input;
};


/// Internals shared by the GPU chain, its CPU reference and the tests.
namespace sparse {

/// One 1-D filter op of the chain along one axis (Gaussian taps or a box max / min).
enum class OpKind : std::uint32_t { kGauss = 0, kMax = 1, kMin = 2 };  // = ISOTOUCH_SPARSE_OP_*
struct Op {
  int axis = 0;             ///< 0 x, 1 y, 2 z
  int radius = 0;           ///< taps each side [voxels]
  OpKind kind = OpKind::kGauss;
  std::uint32_t w_offset = 0;  ///< first weight of a Gaussian op in Plan::weights
};

/// What the pass list means on one grid: the 1-D ops in order, their weights, the total
/// radius and the raw region a candidate brick reads.
struct Plan {
  std::vector<Op> ops;
  std::vector<float> weights;
  std::array<int, 3> radius{0, 0, 0};     ///< R: sum of the ops' radii per axis [voxels]
  std::array<int, 3> region{11, 11, 11};  ///< raw region per candidate: 11 + 2 R (brick - 1 .. + 9, + R)
  std::array<int, 3> reach{1, 1, 1};      ///< bricks each side the widened range spans: floor(R / 8) + 1
  double rel_eps = 0;   ///< relative widening of a range for the Gaussians' float rounding
  bool closing = false; ///< a box max/min is in the chain (an all-NaN window gives +-Inf)
  std::string text;     ///< human-readable op list (describe)
};

/// Empty if `passes` suits the sparse chain (filters, then one gradient; brick_minmax only
/// with halo 1, the halo the selection uses), else the reason naming the pass.
std::string validate(const std::vector<PassDesc>& passes);
/// @throws VolumeError naming `what` if a kernel is too wide.
Plan make_plan(const core::Grid& grid, const std::vector<PassDesc>& passes, const std::string& what);

/// Per-brick raw ranges (no halo): min / max of the finite voxels (NaN skipped) and whether
/// a NaN voxel was seen. Filled one z-slice at a time. The live field keeps them to see which
/// edited bricks changed.
struct RawRanges {
  std::array<int, 3> bricks{0, 0, 0};
  std::vector<float> lo, hi;
  std::vector<std::uint8_t> nan;
  void init(const core::Grid& grid);
  void add_slice(const core::Grid& grid, int z, const float* slice);
  /// Recompute entry `id` alone from `voxels` (the whole volume, x fastest): the same
  /// values and fold order (z, y, x ascending) as add_slice over every slice. After an
  /// edit of brick `id` (session/live_field.h). Requires init(grid) and id < bricks total.
  void set_brick(const core::Grid& grid, const float* voxels, std::uint32_t id);
};

/// Candidate selection: every brick's raw range over exactly the window its smoothed brick
/// + 1 voxel reads (voxels 8 b - 1 - R .. 8 b + 8 + R per axis, clipped to the grid),
/// widened by the Gaussians' rounding bound (conservative: the smoothed field over the
/// brick + 1 voxel lies inside it).
struct Selection {
  std::vector<float> lo, hi;              ///< widened range per brick
  std::vector<std::uint8_t> nan;          ///< a NaN voxel in the window
  std::vector<std::uint32_t> candidates;  ///< ascending brick ids
};
/// `voxels`: the whole volume of `grid`, x fastest; `threads` > 1 splits the slices (the
/// same bits for any count). `copy_to` (optional, voxel_count() floats): also receives a
/// copy of the voxels, written while they are read (the GPU chain's input field).
Selection select(const core::Grid& grid, const float* voxels, const Plan& plan, const core::Isosurface& iso,
                 unsigned threads = 1, float* copy_to = nullptr);

/// select()'s result for one brick (its widened range, NaN flag and whether it is a
/// candidate), bit for bit the same (min / max over the same window; the order of the folds
/// does not change them, -0 is made +0). For the live field (session/live_field.h), which
/// re-selects only the bricks an edit can reach (those whose window holds a changed voxel).
struct BrickSelection {
  float lo, hi;
  bool nan;
  bool candidate;
};
BrickSelection select_brick(const core::Grid& grid, const float* voxels, const Plan& plan,
                            const core::Isosurface& iso, std::uint32_t id);

/// The voxels select_brick() reads for brick index `b` along an axis of `n` voxels with
/// filter radius `r` (Plan::radius): [8b - 1 - r, 8b + 8 + r] clipped to [0, n - 1],
/// both ends included (index frame).
inline std::pair<int, int> brick_window(int b, int r, int n) {
  return {std::max(8 * b - 1 - r, 0), std::min(8 * b + 8 + r, n - 1)};
}

/// Upper bound on the loop back-edges sparse_brick.comp executes for one candidate brick
/// of `plan` (interior brick, every loop counted with its exit test). llvmpipe / lavapipe
/// ends EVERY loop of a shader invocation once 65535 back-edges have run in total
/// (LP_MAX_TGSI_LOOP_ITERATIONS, one counter shared by all loops), silently: a workgroup
/// must not loop over more than kLoopBudget / this bound bricks.
std::uint64_t loop_trips_per_brick(const Plan& plan);
/// Back-edges one workgroup may spend (3/4 of llvmpipe's 65535, a margin for the compiler).
inline constexpr std::uint64_t kLoopBudget = 49151;
/// Bricks one workgroup may loop over: kLoopBudget / loop_trips_per_brick, at least 1.
std::uint64_t max_bricks_per_workgroup(const Plan& plan);

/// The float that gives the same comparisons with float values as the double tau:
/// kAbove the largest float <= tau, kBelow the smallest float >= tau.
float threshold(const core::Isosurface& iso);

/// Exact range of one candidate (smoothed brick + 1 voxel): lo, hi, NaN seen.
struct CandidateRange {
  float lo, hi;
  bool nan;
};
/// Each candidate's exact range over its brick + 1 voxel (voxels 8 b - 1 .. 8 b + 8 per
/// axis, clipped to the grid) of the field `f` of `grid` (x fastest): CandidateCpu::range's
/// values bit for bit (min / max of the non-NaN voxels do not depend on the order of the
/// folds; -0 made +0). `threads` split the candidates (the same bits for any count).
std::vector<CandidateRange> candidate_ranges(const core::Grid& grid, const float* f,
                                             const std::vector<std::uint32_t>& candidates, unsigned threads = 1);
/// The active rule (core::bricked_input_from_dense): not uniform by tile_value, or
/// uniform inside with a NaN voxel. Writes the tile of a uniform brick.
bool is_active(const CandidateRange& r, const core::Isosurface& iso, float background, float& tile);

/// The voxels one stage of the list strategy computes around every candidate brick b:
/// 8 b - lo .. 8 b + 7 + hi along each axis (clipped to the grid); along x lo and hi are
/// multiples of 4 (whole quads, ISOTOUCH_DENSE_VOXELS).
struct Extent {
  std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
};
/// The extents of the list strategy's filter ops, worked backwards from what the host reads
/// of the last one's output (the candidate range, 8 b - 1 .. 8 b + 8, and the gradient's
/// input for the 9^3 samples, 8 b - 1 .. 8 b + 9): each op's output (whole quads along x)
/// widened by its radius along its axis is what the op before it must give. Entry k: op k's
/// output.
std::vector<Extent> list_extents(const Plan& plan);

/// One stage's work list: the quads (4 voxels of an x-row) of the union of the candidates'
/// extents, each once, as units of at most ISOTOUCH_LIST_QUADS quads of one row (two floats
/// each, shaders/work_list.glsl), sorted by z then y then x.
struct WorkList {
  std::vector<float> units;               ///< 2 per unit: y + ny z, q0 * ISOTOUCH_LIST_PACK + quads
  std::vector<std::uint32_t> z_first;     ///< nz + 1 entries: the first unit of slice z
  std::uint64_t quads = 0;                ///< quads in all
  std::size_t unit_count() const { return units.size() / 2; }
};
/// @throws VolumeError naming `what` if the grid is too large for exact float texels (rows
///         or quads per row of 2^24 and more).
WorkList make_work_list(const core::Grid& grid, const std::vector<std::uint32_t>& candidates, const Extent& e,
                        const std::string& what);

/// The fused Gaussian's work list (shaders/gauss_fused_list.comp): columns of output quads,
/// one unit per (x-quad q, slice z, rows y0 .. y0 + n - 1), n < ISOTOUCH_LIST_PACK, covering
/// the union of the candidates' extents `e` (the last filter's, list_extents()), each quad
/// once; units are two floats, q + QX z and y0 * ISOTOUCH_LIST_PACK + n, sorted by z and
/// within a slice by n, longest first.
/// `pairs` (the shader's PAIRS): the first float is 2 (q + QX z) + pair, pair 1 meaning the
/// unit also covers the same rows of slice z + 1 (slices paired two by two, z even, where
/// both need the rows; z_first counts a pair in its first slice).
/// `threads` > 1 (pairs only): the slice pairs split among that many threads, each its
/// own part (the same list for any count).
/// @throws VolumeError naming `what` if the grid is too large for exact float texels.
WorkList make_column_list(const core::Grid& grid, const std::vector<std::uint32_t>& candidates, const Extent& e,
                          const std::string& what, bool pairs = false, unsigned threads = 1);
/// Whether the fused Gaussian of `plan` runs on paired slices (make_column_list's pairs):
/// where the z kernel reaches a neighbouring slice (radius >= 1: the pair shares the x and
/// y passes of 2 r slices). Measured on llvmpipe with the shader's constant loops unrolled
/// ([[unroll]]): the chest CT at -500 HU (radius 1 along z) takes 18.4-18.6 ms of CPU time
/// per run paired against 20.2 single (without the unroll hints, 46 against 21.6: its
/// arrays were not registers); the head CT (radius 2) ran faster paired before too.
bool fused_pairs(const Plan& plan);
/// Whether `plan` is one Gaussian (x, y, z, in that order) that gauss_fused_list.comp can run:
/// radii <= ISOTOUCH_FUSED_MAX_RADIUS and rows of whole quads (nx a multiple of 4).
bool fusable(const Plan& plan, const core::Grid& grid);

class BrickCpu;
/// run_sparse_cpu's per-candidate computation, one brick at a time (the live field
/// recomputes the bricks an edit changed with it): range() smooths the brick's raw region
/// and returns its exact range (smoothed brick + 1 voxel), samples() the 9^3 samples of
/// the brick of the last range() call (beyond the grid: {background, 0, 0, 0}). Bit for
/// bit what run_sparse_cpu computes (and so the GPU chain). Holds references to `vol` and
/// `plan`: they must outlive it.
class CandidateCpu {
 public:
  CandidateCpu(const Volume& vol, const Plan& plan);
  ~CandidateCpu();
  CandidateCpu(const CandidateCpu&) = delete;
  CandidateCpu& operator=(const CandidateCpu&) = delete;
  CandidateRange range(std::uint32_t id);
  void samples(core::Sample* out, float background) const;

 private:
  std::unique_ptr<BrickCpu> impl_;
};

/// Builds the published field: active candidates (is_active on `ranges[c]`) with the
/// 729 samples `samples(c)` returns for candidate index c, tiles of the others (from the
/// exact range for candidates, from the widened range otherwise); fills out.stats,
/// out.field (core::make_bricked_field) and, with keep_input, out.input.
/// `recycler` (optional): the pool is taken from it and its buffer handed back to it when
/// the published store dies (pool_recycler.h); null: a fresh pool, freed with the store.
void publish(const core::Grid& grid, const Selection& sel, const std::vector<CandidateRange>& ranges,
             const std::function<const core::Sample*(std::size_t)>& samples, const core::Isosurface& iso,
             float background, core::SampleFormat format, bool keep_input, SparseOutput& out,
             const std::shared_ptr<PoolRecycler>& recycler = nullptr);
/// The 9^3 samples of brick `b` (brick coordinates; i + 9 j + 81 k) from the dense field `f`
/// of `grid`: value and gradient with the float operations of compute_samples_cpu (central
/// differences inside, one-sided at the borders), so bit for bit the dense chain's samples;
/// beyond the grid {background, 0, 0, 0}. Reads f at the brick's voxels - 1 .. + 9.
void brick_samples(const core::Grid& grid, const float* f, const std::array<int, 3>& b, float background,
                   core::Sample* out);
/// publish() with the active candidates' samples written straight into the pool:
/// `fill(c, dst)` writes ALL 729 samples of candidate index c at dst (the pool is not
/// cleared before: core::SamplePool), called from `threads`
/// threads at once (each on its own candidates; 1: this thread only). `recycler` as publish's.
void publish_fill(const core::Grid& grid, const Selection& sel, const std::vector<CandidateRange>& ranges,
                  const std::function<void(std::size_t, core::Sample*)>& fill, unsigned threads,
                  const core::Isosurface& iso, float background, core::SampleFormat format, bool keep_input,
                  SparseOutput& out, const std::shared_ptr<PoolRecycler>& recycler = nullptr);

}  // namespace sparse

/// The GPU sparse chain. The pass list is filters (gaussian, closing) then gradient
/// (required: a snapshot carries gradients); brick_minmax is implied.
class SparseChain {
 public:
  /// @return error (no throw) if the list is invalid for the sparse path.
  static Result<std::unique_ptr<SparseChain>> create(VulkanContext& ctx, std::vector<PassDesc> passes);
  ~SparseChain();
  SparseChain(const SparseChain&) = delete;
  SparseChain& operator=(const SparseChain&) = delete;

  /// @param iso the isosurface that selects the bricks; @param background the value
  ///        outside the grid in the published field.
  /// @throws VolumeError naming the volume on a resource or size problem.
  SparseOutput run(const Volume& volume, const core::Isosurface& iso, float background,
                   core::SampleFormat format = core::SampleFormat::kFp32, std::uint64_t max_binding_bytes = 0);
  /// Passes, pipelines and buffers created / left out, and the last run's brick counts.
  std::string describe() const;
  /// Also return the BrickedInput in SparseOutput::input (a copy of the pool; tests).
  void set_keep_input(bool keep);
  /// Workgroups per dispatch at most (0: the default, chosen for speed on lavapipe). Never
  /// fewer than the loop budget needs (sparse::max_bricks_per_workgroup); tests set 1 to
  /// make every workgroup loop over as many bricks as allowed.
  void set_max_workgroups(std::uint32_t groups);
  /// How the candidates are computed. Dense: the dense chain's x4 passes
  /// (PassChain, current shaders) over the whole volume, read in place, then per candidate
  /// its exact range (smoothed brick + 1 voxel) and the 9^3 samples of the active ones
  /// gathered on the host - the dense passes reach lavapipe's speed, and a candidate's
  /// samples are by definition the dense chain's. PerBrick: sparse_brick.comp, one
  /// shared-memory workgroup per candidate brick recomputing its own halo (kept for
  /// comparison). All three give the same bits.
  /// Lists (the default): the dense filters' x4 shader on work lists (filter_list_x4.comp):
  /// each pass computes only the quads of the candidate bricks dilated by the rest of the
  /// stencil (sparse::list_extents), halos shared between neighbouring candidates and
  /// computed once, dense-addressed buffers read in place; then on the host the candidates'
  /// ranges and the active ones' samples computed straight into the published pool
  /// (sparse::brick_samples: the gradient's 16 B per voxel are never written twice). A
  /// filter wider than ISOTOUCH_DENSE_MAX_RADIUS runs as Dense.
  enum class Strategy { Lists, Dense, PerBrick };
  void set_strategy(Strategy s);
  /// Bytes this chain holds for no live snapshot: the brick-pool buffer of a published
  /// field already destroyed, kept for the next run's pool (engine/pool_recycler.h: at most
  /// one, the largest). Counted in the process's RSS like any memory.
  std::uint64_t retained_pool_bytes() const;
  /// Runs whose pool was a retained buffer (no fresh pages to fault in).
  std::uint64_t recycled_pools() const;

 private:
  friend class SparseFilter;  // runs the list strategy's filter stage on chosen candidates
  struct Impl;
  explicit SparseChain(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The list strategy's filter stage alone, on chosen candidate bricks of a volume kept on the
/// device and patched brick by brick: the live field's GPU recompute (session/live_field.h).
/// The same kernels and the same work lists as SparseChain::Strategy::Lists: one Gaussian as
/// the fused gauss_fused_list pass, other chains one filter_list_x4 pass per op, each over
/// the quads of the candidates' extents (sparse::list_extents: the candidate bricks dilated
/// by the rest of the stencil, halos shared between neighbouring candidates and computed
/// once). The host then computes ranges and samples from the output exactly as the chain
/// does (sparse::candidate_ranges, sparse::brick_samples): bit for bit run_sparse_cpu.
class SparseFilter {
 public:
  /// Copies `vol` to the device (its grid and path are kept; its voxels are not referenced
  /// afterwards) and makes the pipelines (one empty run).
  /// @return error (no throw) if the pass list does not suit the sparse chain, has no filter
  ///         (a gradient alone needs no GPU pass), a filter wider than
  ///         ISOTOUCH_DENSE_MAX_RADIUS, or a buffer or pipeline cannot be made.
  static Result<std::unique_ptr<SparseFilter>> create(VulkanContext& ctx, const Volume& vol,
                                                      const std::vector<PassDesc>& passes, bool staging = false);
  ~SparseFilter();
  SparseFilter(const SparseFilter&) = delete;
  SparseFilter& operator=(const SparseFilter&) = delete;

  /// Copies bricks `bricks` (ids as in core/brick_field.h) of `voxels` (a whole volume of the
  /// grid given to create(), x fastest) into the device's copy (where device memory is not
  /// host-visible: into a staging copy, uploaded by the next filter()).
  void set_bricks(const float* voxels, const std::vector<std::uint32_t>& bricks) noexcept;

  struct Output {
    const float* field = nullptr;  ///< the last filter's output, dense-addressed (x fastest)
    std::uint64_t quads = 0;       ///< quads computed over all passes
    std::size_t dispatches = 0;
    double lists_ms = 0;           ///< work lists (host)
    double submit_wall_ms = 0;     ///< submit to fence
  };
  /// Runs the filters on the quads of the extents of `candidates` (ascending brick ids).
  /// Output::field is exact at voxels 8 b - 1 .. 8 b + 9 (clipped to the grid) of every
  /// candidate b, what the host reads for its range and samples; elsewhere it holds anything.
  /// Valid until the next call of filter() or set_bricks().
  /// @throws VolumeError naming the volume on a resource or size problem.
  Output filter(const std::vector<std::uint32_t>& candidates);
  /// Kernels and buffers, and where the voxels are copied.
  std::string describe() const;

 private:
  struct Impl;
  explicit SparseFilter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The CPU reference of the sparse chain: the same bricks, the same samples (bit for bit
/// with the dense CPU chain at every published voxel). One thread by default (the
/// reference); `threads` > 1 is the multi-threaded CPU backend (where no Vulkan device
/// exists): the candidates split among that many threads, the same bits.
/// @param keep_input also return the BrickedInput in SparseOutput::input.
/// @param recycler optional: the published pool is taken from it and handed back to it when
///        the snapshot dies (pool_recycler.h), as SparseChain's; null: a fresh pool.
SparseOutput run_sparse_cpu(const Volume& volume, const std::vector<PassDesc>& passes, const core::Isosurface& iso,
                            float background, core::SampleFormat format = core::SampleFormat::kFp32,
                            bool keep_input = false, unsigned threads = 1,
                            const std::shared_ptr<PoolRecycler>& recycler = nullptr);

}  // namespace isotouch::engine
