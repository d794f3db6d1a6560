// edit_mirror.h - the edited volume as `isotouch serve` saves and sends it: a copy of the
// session's voxels that the edit thread keeps up to date brick by brick (an EditListener,
// not real time), and the box of voxels changed since it was last taken (the sub-volume
// of the next IMAGE sent back). Part of isotouch::serve.
#pragma once
#include <mutex>

#include "isotouch/engine/volume.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/session/live_session.h"

namespace isotouch::service {

class EditMirror {
 public:
  /// Starts as `v` (copied: the session's volume before any edit).
  explicit EditMirror(const engine::Volume& v);
  /// The listener to give the LiveSession of `es` (whose volume this mirrors): copies the
  /// bricks each applied edit changed (a brush's dirty bricks, an undo's or redo's restored
  /// ones) and grows the changed box. `this` and `es` must outlive the session.
  session::EditListener listener(const session::EditSession& es);
  /// The edited volume (statistics updated). Any thread.
  engine::Volume volume() const;
  /// The box changed since the last call (empty: nothing changed); the box is cleared. No
  /// voxel is copied. Any thread.
  VoxelBox take_changed() const;
  /// Copies the voxels of `box` (inside the volume) into `out`, x fastest, then y, then z: the
  /// lock (which the edit thread's listener takes) is held for one slice at a time, never for
  /// the whole copy. A brick written meanwhile is in the changed box again (the next take).
  void copy_box(const VoxelBox& box, float* out) const;
  /// Gives back a box take_changed returned whose voxels could not be sent: it joins the
  /// box the next take_changed returns. Any thread.
  void restore_changed(const VoxelBox& box) const;
  /// Edits seen by the listener so far.
  long edits() const;

 private:
  void copy_bricks(const engine::Volume& from, const std::vector<std::uint32_t>& ids);

  mutable std::mutex mu_;
  engine::Volume v_;
  mutable VoxelBox changed_;
  long edits_ = 0;
};

}  // namespace isotouch::service
