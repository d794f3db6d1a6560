// edit_history.h - per-stroke undo / redo of volume edits as brick backups.
//
// Bricks: the 8^3 bricks of core/brick_field.h, ids linear, x fastest, ceil(dims / 8) per
// axis; brick (bx, by, bz) holds the voxels [8 bx, min(8 bx + 8, nx)) x ... (clipped at the
// far borders). A backup is the brick's raw float voxels (engine::Volume::voxels, file
// units), row by row, x fastest: 4 bytes per voxel of the clipped brick.
//
// A stroke (begin_stroke .. end_stroke) records the pre-edit content of every brick it
// touches for the FIRST time (a brick touched again in the same stroke keeps its first
// backup). end_stroke drops the backups of bricks whose content did not change (bit for
// bit). Undo swaps the stroke's backups with the volume's current content of those
// bricks, so the stroke then holds the post-edit content and redo swaps back: both
// directions restore bit for bit. A new stroke after undo drops the redo branch.
// Memory limit: the payload bytes (undo + redo strokes and the open stroke) are kept under
// `limit_mib` MiB by dropping the oldest undo strokes first (counted in dropped_strokes());
// the open stroke is never dropped while it is open, so it may exceed the limit until
// end_stroke, where it is dropped too if it alone exceeds the limit.
#pragma once
#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <vector>

#include "isotouch/engine/volume.h"

namespace isotouch::session {

/// Voxels [lo, hi) of brick `id` of `grid` (clipped to the grid), index space.
struct BrickBox {
  std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
  std::size_t voxels() const {
    return std::size_t(hi[0] - lo[0]) * std::size_t(hi[1] - lo[1]) * std::size_t(hi[2] - lo[2]);
  }
};
/// @throws std::out_of_range naming the id and the brick count if `id` is not a brick of `grid`.
BrickBox brick_box(const core::Grid& grid, std::uint32_t id);
/// Number of 8^3 bricks of `grid` (ceil(dims / 8) product).
std::size_t brick_total(const core::Grid& grid);
/// The brick's voxels, x fastest over the clipped box.
std::vector<float> read_brick(const engine::Volume& vol, std::uint32_t id);
/// Writes `data` (brick_box(id).voxels() floats, x fastest) into the brick.
void write_brick(engine::Volume& vol, std::uint32_t id, const float* data);
/// Copies brick `id` of `from` (a volume of vol's grid, x fastest) into vol, row by row.
/// @throws std::out_of_range for an id past the grid's bricks, std::invalid_argument for a
/// volume whose voxel count is not its grid's.
void copy_brick(engine::Volume& vol, std::uint32_t id, const float* from);

/// Undo / redo history of strokes over one engine::Volume (CPU side).
class EditHistory {
 public:
  /// @param limit_mib payload limit [MiB] (1 MiB = 2^20 bytes); must be >= 0.
  explicit EditHistory(double limit_mib = 256.0);

  /// Opens a stroke and drops the redo branch. @throws std::logic_error if one is open.
  void begin_stroke();
  bool stroke_open() const { return open_.has_value(); }
  /// Records the pre-edit content of the bricks in `ids` not yet recorded in the open
  /// stroke. Call BEFORE the edit changes them. @throws std::logic_error if no stroke is open.
  void record(const engine::Volume& vol, const std::vector<std::uint32_t>& ids);
  /// The same from `voxels`, a volume of `grid` (x fastest) that holds the bricks' pre-edit
  /// content, so that the edit may already have changed them (e.g. LiveField::published_voxels()
  /// before its update lets it follow the volume). @throws std::logic_error if no stroke is
  /// open, std::out_of_range for an id past the grid's bricks.
  void record(const core::Grid& grid, const float* voxels, const std::vector<std::uint32_t>& ids);
  /// Closes the open stroke: drops its unchanged backups (bit-identical to `vol`), pushes it
  /// on the undo stack if anything changed, enforces the memory limit (oldest strokes first).
  /// A stroke larger than the limit alone is a barrier: it and every older stroke are
  /// dropped (undo stops there). No-op if none is open. @throws std::invalid_argument for
  /// a volume whose voxel count is not its grid's (the stroke then stays open).
  void end_stroke(const engine::Volume& vol);

  /// Undoes the newest stroke (ends an open stroke first). Returns the restored brick ids
  /// (ascending; empty if there was nothing to undo) and calls the on_restore hook with them.
  /// @throws what the hook throws (or std::bad_alloc): then the volume and both stacks are
  ///         as they were (the hook is called again with the restored content).
  std::vector<std::uint32_t> undo(engine::Volume& vol);
  /// Redoes the newest undone stroke; same return, hook and failure as undo().
  std::vector<std::uint32_t> redo(engine::Volume& vol);
  /// Forgets the newest undo stroke without restoring it (its edit was rolled back by the
  /// caller, so undoing it would change nothing) and gives back the redo branch that
  /// stroke's begin_stroke() dropped. Call it right after that stroke ended. No-op if there
  /// is no undo stroke.
  void discard_newest_stroke();
  /// Forgets every stroke: undo, redo and what the open one recorded (each counted in
  /// dropped_strokes()), e.g. when an edit that stands could not record its undo step:
  /// undoing older strokes past it would give a state that never existed. An open stroke
  /// stays open, empty, under a new serial (the rest of a press is still one step). Allocates
  /// nothing, throws nothing.
  void clear() noexcept;
  /// Serial numbers of strokes (1, 2, ... in the order they were opened): the open stroke's
  /// and the newest undo stroke's, 0 for none. A stroke that ended with no change, or was
  /// dropped by the memory limit, is never the newest undo stroke.
  std::uint64_t open_stroke_serial() const { return open_ ? open_->serial : 0; }
  std::uint64_t newest_stroke_serial() const { return undo_.empty() ? 0 : undo_.back().serial; }

  /// Called with the restored brick ids after undo / redo changed `vol` (e.g. to upload
  /// them to the GPU copy of the volume).
  void set_on_restore(std::function<void(const std::vector<std::uint32_t>&)> hook) { on_restore_ = std::move(hook); }

  std::size_t undo_depth() const { return undo_.size(); }
  std::size_t redo_depth() const { return redo_.size(); }
  /// Payload bytes held now: 4 per backed-up voxel, undo + redo + the open stroke.
  std::uint64_t bytes() const { return bytes_; }
  std::uint64_t limit_bytes() const { return limit_; }
  /// Strokes dropped so far: to stay under the limit (oldest first), and by clear().
  std::size_t dropped_strokes() const { return dropped_; }

 private:
  struct Stroke {
    std::map<std::uint32_t, std::vector<float>> bricks;  ///< id -> content (pre-edit, or post-edit once undone)
    std::uint64_t bytes = 0;
    std::uint64_t serial = 0;  ///< begin_stroke's count: which stroke this is
  };
  std::vector<std::uint32_t> swap_in(Stroke& s, engine::Volume& vol);
  void enforce_limit();

  std::deque<Stroke> undo_;  ///< oldest first
  std::vector<Stroke> redo_; ///< newest undone last
  std::vector<Stroke> dropped_redo_;  ///< the redo branch the newest stroke dropped (discard_newest_stroke gives it back)
  std::optional<Stroke> open_;
  std::uint64_t bytes_ = 0, limit_ = 0;
  std::size_t dropped_ = 0;
  std::uint64_t serials_ = 0;  ///< strokes opened so far
  std::function<void(const std::vector<std::uint32_t>&)> on_restore_;
};

}  // namespace isotouch::session
