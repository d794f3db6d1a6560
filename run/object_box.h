// object_box.h - where the object is in its scan: the box the pictures of a whole object
// (`isotouch render`, the run's overview) aim at, robust to +Inf/NaN voxels and to stray
// bright voxels far from the object.
//
// Frames: boxes are grid-world [m] (origin + spacing * index, voxel centres).
#pragma once
#include <optional>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/engine/volume.h"

namespace isotouch::run {

/// An axis-aligned box of voxel centres [m, grid-world].
struct ObjectBox {
  core::Vec3 low, high;
};

/// The object's box: the finite voxels inside `iso` (+Inf and NaN never count), grouped in
/// 6-connected components; the box spans every component of at least 1 % of the largest's
/// voxel count, so an isolated voxel or speck far from the object does not stretch it while
/// an object in a few pieces is framed whole. None when no finite voxel is inside.
std::optional<ObjectBox> object_box(const engine::Volume& vol, const core::Isosurface& iso);

/// `cam` aimed at the centre of object_box and, when cam.distance_m is 0 (fit), placed where
/// that box's bounding sphere (plus a voxel each side) fills the view's height, as orbit_view
/// fits the whole volume; `cam` unchanged when no voxel is inside. The angles, zoom and up are
/// kept. The one framing `isotouch render` and the run's overview share.
engine::OrbitCamera frame_object(engine::OrbitCamera cam, const engine::Volume& vol, const core::Isosurface& iso);

}  // namespace isotouch::run
