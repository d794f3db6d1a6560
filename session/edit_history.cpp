// edit_history.cpp - per-stroke undo / redo as brick backups (see edit_history.h).
#include <algorithm>
#include "isotouch/session/edit_history.h"

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>

#include "isotouch/core/brick_field.h"

namespace isotouch::session {
using engine::Volume;

std::size_t brick_total(const core::Grid& grid) {
  const auto nb = core::brick_counts(grid);
  return std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]);
}

BrickBox brick_box(const core::Grid& grid, std::uint32_t id) {
  const auto nb = core::brick_counts(grid);
  if (grid.empty() || id >= brick_total(grid))
    throw std::out_of_range("brick id " + std::to_string(id) + " out of range: the grid has " +
                            std::to_string(brick_total(grid)) + " bricks");
  const std::uint32_t b[3] = {id % std::uint32_t(nb[0]), (id / std::uint32_t(nb[0])) % std::uint32_t(nb[1]),
                              id / (std::uint32_t(nb[0]) * std::uint32_t(nb[1]))};
  BrickBox box;
  for (std::size_t a = 0; a < 3; ++a) {
    box.lo[a] = int(b[a]) * core::kBrickSize;
    box.hi[a] = std::min(box.lo[a] + core::kBrickSize, grid.dims[a]);
  }
  return box;
}

namespace {
/// Calls f(offset in the volume, offset in the brick, row length) for every x-row of the brick.
template <class F>
void for_rows(const core::Grid& g, const BrickBox& b, F&& f) {
  const std::size_t row = std::size_t(b.hi[0] - b.lo[0]);
  std::size_t k = 0;
  for (int z = b.lo[2]; z < b.hi[2]; ++z)
    for (int y = b.lo[1]; y < b.hi[1]; ++y, k += row) f(g.index(b.lo[0], y, z), k, row);
}
void check_volume(const Volume& vol) {
  if (vol.voxels.size() != vol.grid.voxel_count())
    throw std::invalid_argument(vol.path + ": volume has " + std::to_string(vol.voxels.size()) + " voxels for " +
                                std::to_string(vol.grid.voxel_count()) + " grid points");
}
/// Whether brick `id` of `vol` holds `data` (read_brick()'s layout), bit for bit; reads in
/// place (no copy, no allocation).
bool brick_holds(const Volume& vol, std::uint32_t id, const float* data) {
  const BrickBox b = brick_box(vol.grid, id);
  bool same = true;
  for_rows(vol.grid, b, [&](std::size_t v, std::size_t k, std::size_t n) {
    same = same && std::memcmp(vol.voxels.data() + v, data + k, n * sizeof(float)) == 0;
  });
  return same;
}
/// Brick `id` of `voxels`, a volume of `grid` (x fastest), in read_brick()'s layout.
std::vector<float> read_box(const core::Grid& grid, const float* voxels, std::uint32_t id) {
  const BrickBox b = brick_box(grid, id);
  std::vector<float> out(b.voxels());
  for_rows(grid, b, [&](std::size_t v, std::size_t k, std::size_t n) {
    std::memcpy(out.data() + k, voxels + v, n * sizeof(float));
  });
  return out;
}
}  // namespace

std::vector<float> read_brick(const Volume& vol, std::uint32_t id) {
  check_volume(vol);
  return read_box(vol.grid, vol.voxels.data(), id);
}

void write_brick(Volume& vol, std::uint32_t id, const float* data) {
  check_volume(vol);
  const BrickBox b = brick_box(vol.grid, id);
  for_rows(vol.grid, b, [&](std::size_t v, std::size_t k, std::size_t n) {
    std::memcpy(vol.voxels.data() + v, data + k, n * sizeof(float));
  });
}

void copy_brick(Volume& vol, std::uint32_t id, const float* from) {
  check_volume(vol);
  (void)brick_box(vol.grid, id);  // std::out_of_range for an id past the grid's bricks
  core::copy_brick_voxels(vol.grid, id, from, vol.voxels.data());
}

EditHistory::EditHistory(double limit_mib) {
  if (!(limit_mib >= 0) || !std::isfinite(limit_mib))
    throw std::invalid_argument("EditHistory: field 'limit_mib' must be a finite number >= 0, got " +
                                std::to_string(limit_mib));
  // Clamped below 2^63 bytes: a larger double does not convert to uint64 (undefined).
  limit_ = std::uint64_t(std::min(limit_mib * 1048576.0, 9.2e18));
}

void EditHistory::begin_stroke() {
  if (open_) throw std::logic_error("EditHistory::begin_stroke: a stroke is already open (end_stroke first)");
  for (const Stroke& s : redo_) bytes_ -= s.bytes;
  dropped_redo_ = std::move(redo_);  // kept (not counted) until the next stroke, undo or redo
  redo_.clear();
  open_ = Stroke{};
  open_->serial = ++serials_;
}

void EditHistory::record(const Volume& vol, const std::vector<std::uint32_t>& ids) {
  check_volume(vol);
  record(vol.grid, vol.voxels.data(), ids);
}

void EditHistory::record(const core::Grid& grid, const float* voxels, const std::vector<std::uint32_t>& ids) {
  if (!open_) throw std::logic_error("EditHistory::record: no open stroke (begin_stroke first)");
  for (std::uint32_t id : ids) {
    if (open_->bricks.count(id)) continue;  // first touch in this stroke only
    std::vector<float> data = read_box(grid, voxels, id);
    const std::uint64_t n = data.size() * sizeof(float);
    open_->bricks.emplace(id, std::move(data));
    open_->bytes += n;
    bytes_ += n;
  }
}

void EditHistory::end_stroke(const Volume& vol) {
  if (!open_) return;
  check_volume(vol);
  Stroke s = std::move(*open_);
  open_.reset();
  for (auto it = s.bricks.begin(); it != s.bricks.end();) {
    if (brick_holds(vol, it->first, it->second.data())) {  // unchanged: no undo data kept
      const std::uint64_t n = it->second.size() * sizeof(float);
      s.bytes -= n;
      bytes_ -= n;
      it = s.bricks.erase(it);
    } else {
      ++it;
    }
  }
  if (s.bytes > limit_) {
    // A stroke that alone exceeds the limit cannot be kept, and it is a barrier: undoing an
    // older stroke past it would restore that stroke's bricks under this one's changes, a
    // state that never existed. The older strokes go with it.
    bytes_ -= s.bytes;
    ++dropped_;
    for (const Stroke& old : undo_) bytes_ -= old.bytes;
    dropped_ += undo_.size();
    undo_.clear();
  } else if (!s.bricks.empty()) {
    undo_.push_back(std::move(s));
  }
  enforce_limit();
}

void EditHistory::enforce_limit() {
  while (bytes_ > limit_ && !undo_.empty()) {
    bytes_ -= undo_.front().bytes;
    undo_.pop_front();
    ++dropped_;
  }
  // Then the redo strokes farthest from the present (the front of redo_ is redone last).
  while (bytes_ > limit_ && !redo_.empty()) {
    bytes_ -= redo_.front().bytes;
    redo_.erase(redo_.begin());
    ++dropped_;
  }
}

// All or nothing: the volume's content of the stroke's bricks is read before any is written
// (the only allocations), so a failure leaves volume and stroke as they were; a hook that
// throws has the swap taken back (the copy it mirrors is given the old content again, if it
// can take it) before its exception goes on.
std::vector<std::uint32_t> EditHistory::swap_in(Stroke& s, Volume& vol) {
  std::vector<std::uint32_t> ids;
  ids.reserve(s.bricks.size());
  std::vector<std::vector<float>> now;
  now.reserve(s.bricks.size());
  for (const auto& [id, data] : s.bricks) {
    now.push_back(read_brick(vol, id));
    ids.push_back(id);
  }
  auto swap_all = [&] {
    std::size_t k = 0;
    for (auto& [id, data] : s.bricks) {
      write_brick(vol, id, data.data());
      data.swap(now[k++]);
    }
  };
  swap_all();
  if (on_restore_ && !ids.empty()) {
    try {
      on_restore_(ids);
    } catch (...) {
      swap_all();  // back as it was
      try {
        on_restore_(ids);
      } catch (...) {
      }
      throw;
    }
  }
  return ids;
}

// Undo and redo move a stroke between the stacks only once its swap succeeded (the target
// stack's room reserved first): a swap that throws leaves both stacks and the volume as
// they were.
std::vector<std::uint32_t> EditHistory::undo(Volume& vol) {
  end_stroke(vol);
  dropped_redo_.clear();
  if (undo_.empty()) return {};
  redo_.reserve(redo_.size() + 1);
  std::vector<std::uint32_t> ids = swap_in(undo_.back(), vol);
  redo_.push_back(std::move(undo_.back()));
  undo_.pop_back();
  return ids;
}

void EditHistory::discard_newest_stroke() {
  if (undo_.empty()) return;
  bytes_ -= undo_.back().bytes;
  undo_.pop_back();
  // The redo branch that stroke dropped comes back.
  for (const Stroke& s : redo_) bytes_ -= s.bytes;  // none: the stroke's begin emptied it
  for (const Stroke& s : dropped_redo_) bytes_ += s.bytes;
  redo_ = std::move(dropped_redo_);
  dropped_redo_.clear();
  enforce_limit();
}

void EditHistory::clear() noexcept {
  dropped_ += undo_.size() + redo_.size() + (open_ ? 1 : 0);
  undo_.clear();
  redo_.clear();
  dropped_redo_.clear();
  if (open_) {  // still open (its end_stroke to come), from now on, under a new serial
    open_->bricks.clear();
    open_->bytes = 0;
    open_->serial = ++serials_;
  }
  bytes_ = 0;
}

std::vector<std::uint32_t> EditHistory::redo(Volume& vol) {
  end_stroke(vol);
  dropped_redo_.clear();
  if (redo_.empty()) return {};
  undo_.emplace_back();  // (a deque cannot reserve: the slot is made first, dropped on failure)
  std::vector<std::uint32_t> ids;
  try {
    ids = swap_in(redo_.back(), vol);
  } catch (...) {
    undo_.pop_back();
    throw;
  }
  undo_.back() = std::move(redo_.back());
  redo_.pop_back();
  return ids;
}

}  // namespace isotouch::session
