// edit_floor.h - the smallest program that does an edit's work, for `bench edit`'s floor
// rows: the same brush, the passes on the bricks whose published samples it can change,
// a snapshot published. What the product's path (EditSession: Sculptor + LiveField) costs
// above this is its own overhead; what this costs is the floor of the same work.
#pragma once
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/sparse_chain.h"
#include "isotouch/engine/volume.h"
#include "isotouch/session/brush.h"

namespace isotouch::bench {

/// One edit of the floor program: times [ms] of its stages and what it computed.
struct FloorStep {
  double brush_ms = 0;        ///< session::apply_brush_cpu on the floor's own volume (one thread)
  double passes_ms = 0;       ///< ranges and samples of the reached bricks (sparse::CandidateCpu)
  double snapshot_ms = 0;     ///< the new snapshot: table and tiles copied, new slots written, sealed
  std::size_t dirty = 0;      ///< bricks whose voxels changed
  std::size_t recomputed = 0; ///< bricks whose samples were recomputed
  std::shared_ptr<const core::SampleField> snapshot;  ///< null when the brush changed nothing
};

/// The floor program over a bricked fp32 snapshot: it owns a copy of the volume and a copy
/// of the first snapshot's samples (plus a ring of spare slots). Each step: the brush on
/// the CPU reference; the bricks the changed voxels reach (live_field.h's rule: brick c
/// reads raw voxels [8c - 1 - R, 8c + 9 + R]; the brush's voxel box stands for the changed
/// voxels) recomputed with run_sparse_cpu's per-brick code, active or uniform by the exact
/// range; a new store sharing the pool, with a copied table and tiles. No candidate
/// re-selection, no undo, no shadow copy: less than the product may do, never more.
/// The same snapshot values as the product (tests/test_bench_edit.cpp).
class EditFloor {
 public:
  /// @param vol the volume `first` was built from; @param first its bricked fp32 snapshot.
  /// @throws std::invalid_argument if `first` is not a bricked fp32 snapshot.
  EditFloor(const engine::Volume& vol, const core::SampleField& first, const std::vector<engine::PassDesc>& passes,
            const core::Isosurface& iso, std::size_t spare_slots = 1024);
  /// Applies `b` and builds snapshot `version` (published by the caller).
  /// @throws std::runtime_error when the spare slots run out.
  FloorStep apply(const session::Brush& b, std::uint64_t version);
  const engine::Volume& volume() const { return vol_; }

 private:
  /// The bricks whose published content the brush's voxel box reaches (ascending ids).
  void reached(const session::Brush& b, std::vector<std::uint32_t>& out) const;
  std::uint32_t take_slot();

  engine::Volume vol_;
  engine::sparse::Plan plan_;
  core::Isosurface iso_;
  std::shared_ptr<const core::SampleField> proto_;  ///< grid, background: copied per snapshot
  std::shared_ptr<core::SamplePool> pool_;
  std::vector<std::uint32_t> table_;
  std::vector<core::Sample> tiles_;
  std::vector<std::uint32_t> free_;                       ///< slots no snapshot uses
  std::deque<std::pair<std::uint64_t, std::uint32_t>> retired_;  ///< (step, slot) left at that step
  std::uint64_t step_ = 0;
  std::vector<std::uint32_t> reach_;
};

}  // namespace isotouch::bench
