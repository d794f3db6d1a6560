// sparse_chain.h - the sparse GPU engine (issue 8, item 4): passes computed only on the
// bricks whose value range can straddle the isovalue, published as a bricked SampleField
// (core/brick_field.h). OWNER: gpu-sparse helper. This header is the contract that
// bench engine (apps/bench_engine.cpp) and the scene runner (apps/run_job.cpp) code
// against; the owner may add members but keeps these names and meanings.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "brick_field.h"
#include "passes.h"

namespace isotouch::engine {

/// What a sparse run found and published.
struct SparseStats {
  std::size_t bricks_total = 0;      ///< ceil(dims/8) product
  std::size_t candidates = 0;        ///< bricks computed (raw range, widened by the stencils, straddles tau)
  std::size_t active = 0;            ///< bricks published with samples (smoothed range, halo 1, straddles tau)
  std::uint64_t snapshot_bytes = 0;  ///< bytes of the published snapshot (table + tiles + pool)
  std::uint64_t dense_fp32_bytes = 0;  ///< voxels * 16: the dense fp32 snapshot it replaces
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
};

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

 private:
  struct Impl;
  explicit SparseChain(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// The one-thread CPU reference of the sparse chain: the same bricks, the same samples
/// (bit for bit with the dense CPU chain at every published voxel).
SparseOutput run_sparse_cpu(const Volume& volume, const std::vector<PassDesc>& passes, const core::Isosurface& iso,
                            float background, core::SampleFormat format = core::SampleFormat::kFp32);

}  // namespace isotouch::engine
