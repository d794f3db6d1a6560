// live_field.h - the published snapshot of a volume that is being edited.
// This header is the contract that the scene runner
// (session/edit_session.*), `isotouch bench edit` and `isotouch replay` code against; the owner
// may add members but keeps these names and meanings.
//
// After an edit changed the raw voxels of some bricks (Sculptor returns their ids),
// update() recomputes the scene's passes (gradient, Gaussian, closing: the sparse chain's
// pass list, engine/sparse_chain.h) only where the published samples can change - the
// dirty bricks widened by the stencil's reach plus the gradient and the 1-voxel apron -
// re-decides which of those bricks are active or uniform (the sparse chain's rule:
// core::bricked_input_from_dense / sparse::is_active), and publishes a new bricked
// core::SampleField whose unchanged bricks are SHARED with the previous snapshot (their
// samples are not copied: same pool memory), while the previous snapshot stays valid and
// unchanged for as long as someone (the servo) holds it.
//
// Truth: every snapshot update() returns reads (through core::FieldView) exactly like
// run_sparse_cpu() on the edited volume with the same passes, isosurface, background and
// format (same active set, same tiles, samples bit for bit).
//
// How (live_field.cpp):
// - What an edit can change. The live field keeps a copy of the raw voxels as of its newest
//   snapshot; update() compares each dirty brick with it and takes the box of voxels whose
//   bits changed. Brick b's published content (exact range over the smoothed brick +- 1
//   voxel, samples of voxels 8b .. 8b + 8 with the gradient reading one further) reads raw
//   voxels [8b - 1 - R, 8b + 9 + R] per axis (R: the filters' total radius, sparse::Plan),
//   so the changed box [x0, x1] reaches bricks ceil((x0 - 9 - R) / 8) .. floor((x1 + 1 + R)
//   / 8) ("content" bricks). A dirty brick whose raw range changed also changes the
//   candidate selection of the bricks within the plan's reach (sparse::select): those are
//   re-selected, and recomputed only if they turn candidate. Every other brick keeps its
//   table entry. Recomputed bricks run run_sparse_cpu's own per-brick code
//   (sparse::CandidateCpu, sparse::select_brick): bit for bit the full run (and the GPU).
// - On the GPU (a LiveField created with a Vulkan context, a filter in the pass list): the
//   recomputed bricks' filters run with the sparse chain's list kernels
//   (engine::SparseFilter: the fused Gaussian or filter_list_x4 per op, on the quads of the
//   recomputed bricks dilated by the stencil, halos shared between neighbours and computed
//   once) on a device copy of the volume patched with the changed bricks; ranges and samples
//   are then computed on the host from that output as the sparse chain does
//   (sparse::candidate_ranges, sparse::brick_samples): the same bits. Below
//   gpu_min_bricks() recomputed bricks (small edits, where one submit costs more than the
//   CPU's per-brick work) the CPU path runs; LiveUpdateStats::gpu says which ran. A gradient
//   alone has no filter: no GPU pass, the CPU computes it (describe() says so).
// - Sharing. All snapshots of a LiveField keep their active bricks in one fixed-capacity
//   arena (BrickStore::slot_capacity; never reallocated, so table entries and the servo's
//   pool pointer stay valid); a snapshot has its own table and tiles (4 B per brick + 16 B
//   per uniform brick). A recomputed brick whose new samples equal its old slot's bits
//   keeps the slot; a changed one gets a free slot, written before the snapshot is
//   published, while no live snapshot uses that slot (the servo may read the previous
//   snapshot meanwhile: nothing it reads is written). A slot is in use by the contiguous
//   versions [born, retired); it is freed once no store of those versions is alive (the
//   stores' shared_ptr deleter, under the arena's mutex, never on a read path). When the
//   free slots run out (old snapshots held), the current bricks are copied into a new arena;
//   the old one is retired: it lives until its last snapshot dies, but the memory of every
//   slot no live snapshot uses is given back to the system (madvise), at once and as its
//   snapshots die, so a snapshot held for long (the first one) pins its own slots, not the
//   whole arena.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/engine/volume.h"
#include "isotouch/session/gpu_parts.h"

namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch::session {

class LiveGpuFilter;  // live_gpu.h

struct LiveFieldOptions {
  std::vector<engine::PassDesc> passes{engine::PassDesc{}};  ///< filters then gradient (sparse_chain.h's rule); default: gradient
  core::Isosurface iso;                      ///< selects the active bricks
  float background = 0.f;                    ///< the published background (outside the grid)
  core::SampleFormat format = core::SampleFormat::kFp32;
};

/// What one update() did.
struct LiveUpdateStats {
  std::size_t dirty = 0;        ///< dirty bricks given
  std::size_t recomputed = 0;   ///< bricks whose range / samples were recomputed (dirty + reach)
  std::size_t activated = 0;    ///< bricks uniform before, active now
  std::size_t deactivated = 0;  ///< bricks active before, uniform now
  std::size_t active = 0;       ///< active bricks in the new snapshot
  std::size_t shared = 0;       ///< active bricks whose samples are shared with the previous snapshot
  std::uint64_t new_bytes = 0;  ///< sample bytes written for this snapshot (the rest is shared)
  double recompute_ms = 0;      ///< passes on the recomputed bricks [ms]
  bool gpu = false;             ///< the filters ran on the GPU (else all on the CPU)
  bool gpu_failed = false;      ///< the GPU failed on this update: the CPU ran it, and runs every later one
  double gpu_submit_ms = 0;     ///< with gpu: submit to fence [ms] (inside recompute_ms)
  double publish_ms = 0;        ///< building the new snapshot (table, tiles, pool slots) [ms]
  double total_ms = 0;          ///< update() up to the snapshot committed (not on_commit, not the shadow's copy) [ms]
  std::uint64_t version = 0;    ///< the new snapshot's SampleField::version
};

/// The edited volume's published snapshot, updated brick by brick.
/// Threads: create / update / current / pool_bytes / arena_bytes from one (the editing)
/// thread; the snapshots may be read, copied and released on any thread meanwhile.
/// Memory: a copy of the raw voxels (to find the voxels an edit changed) + the arena.
class LiveField {
 public:
  /// Builds the first snapshot of `vol` (version 1) - the same as run_sparse_cpu.
  /// @throws VolumeError naming the volume, or std::invalid_argument naming the pass, if
  ///         the pass list does not suit the sparse chain.
  static std::unique_ptr<LiveField> create(const engine::Volume& vol, const LiveFieldOptions& options);
  /// The same, recomputing the filters on the GPU of `gpu` (a VulkanContext*: gpu_parts.h;
  /// null: CPU only) for updates of
  /// at least gpu_min_bricks() recomputed bricks. Where the GPU cannot be used (no filter in
  /// the pass list, this build has no Vulkan, the device refuses a buffer or pipeline) the
  /// field recomputes on the CPU and gpu_reason() says why: set-up never fails for it.
  /// The context must outlive the LiveField and be used from the updating thread only meanwhile.
  static std::unique_ptr<LiveField> create(const engine::Volume& vol, const LiveFieldOptions& options,
                                           GpuParts gpu);
  ~LiveField();
  LiveField(const LiveField&) = delete;
  LiveField& operator=(const LiveField&) = delete;

  /// `vol` is the volume create() saw, edited in bricks `dirty` (ids as in
  /// core/brick_field.h, any order, duplicates allowed; ids out of range throw
  /// std::out_of_range naming the id). Returns the new snapshot (version + 1), which
  /// shares every brick the edit could not change with the previous one.
  ///
  /// `on_commit` (if set) is called once with the new snapshot as soon as it is committed
  /// (current() returns it, nothing can be taken back): to publish it at once. It runs
  /// before published_voxels() follows the volume, so that it still reads the content as of
  /// the previous snapshot then (an edit's undo step), and must not throw (std::terminate).
  using OnCommit = std::function<void(const std::shared_ptr<const core::SampleField>&)>;
  std::shared_ptr<const core::SampleField> update(const engine::Volume& vol, const std::vector<std::uint32_t>& dirty,
                                                  LiveUpdateStats* stats = nullptr, const OnCommit& on_commit = {});
  /// Tests only: `fault` runs inside update() once the new table, tiles and slots are
  /// patched, before the store is made; what it throws is handled as update()'s own
  /// failure (nothing published, everything as it was). Empty: none.
  void set_commit_fault_for_test(std::function<void()> fault);
  /// The newest snapshot.
  std::shared_ptr<const core::SampleField> current() const;
  /// The raw voxels of the volume current() was computed from (the grid's, x fastest): an
  /// update that throws leaves them as they were, so an edit can be taken back from them.
  /// While update()'s on_commit runs they are still the previous snapshot's.
  const std::vector<float>& published_voxels() const;
  const LiveFieldOptions& options() const;
  /// Bytes of sample memory held for all snapshots alive now (pool slots in use: 729 samples
  /// of 16 B (fp32) or 8 B (fp16, unorm16), + 32 B of decode parameters for unorm16, per slot).
  std::uint64_t pool_bytes() const;
  /// Bytes of the arenas alive now (every slot, used or free), same units as pool_bytes().
  std::uint64_t arena_bytes() const;
  /// Whether update() may run the filters on the GPU.
  bool gpu_enabled() const;
  /// Why the GPU is not used (empty when it is).
  const std::string& gpu_reason() const;
  /// Recomputed bricks from which update() runs the filters on the GPU (below: the CPU).
  std::size_t gpu_min_bricks() const;
  void set_gpu_min_bricks(std::size_t bricks);
  /// Replaces the GPU filter create() made (null: none, with `reason_if_none` as gpu_reason);
  /// for tests (a filter that fails, one that counts its calls).
  void set_gpu_filter(std::unique_ptr<LiveGpuFilter> filter, const std::string& reason_if_none = "none given");
  /// How update() recomputes: CPU per brick, or the GPU kernels above the threshold.
  std::string describe() const;

 private:
  struct Impl;
  explicit LiveField(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotouch::session
