// grid.h - the regular grid of a volume and its frames. Part of isotouch::core.
#pragma once
#include <array>
#include <cstddef>

#include "isotouch/core/vec3.h"

namespace isotouch::core {

/// Regular grid of voxel centres and the transform world_T_index.
///
/// Frames (docs/architecture.md, "Frames"):
/// - *index*: continuous voxel coordinates, voxel centres at integers, x fastest in memory;
/// - *grid-world* [m], the frame the servo, the device (through the workspace transform)
///   and the renderers work in: world = origin_m + diag(spacing_m) * index. Its axes are
///   the index axes, so trilinear cells are axis-aligned boxes and a force in world axes
///   is a force in device axes;
/// - *physical* [m], the file's frame (ITK, LPS for medical images): physical = origin_m +
///   D (world - origin_m), with D the direction matrix of engine::Volume (direction,
///   to_physical, direction_apply). The servo never needs D, so the grid does not carry it;
///   every point reported to a user goes through engine::Volume::to_physical.
struct Grid {
  std::array<int, 3> dims{0, 0, 0};      ///< voxels along x, y, z
  Vec3 spacing_m{1e-3, 1e-3, 1e-3};      ///< voxel size [m]
  Vec3 origin_m{0, 0, 0};                ///< grid-world position of voxel (0,0,0) centre [m]

  std::size_t voxel_count() const {
    return std::size_t(dims[0]) * std::size_t(dims[1]) * std::size_t(dims[2]);
  }
  bool empty() const { return dims[0] <= 0 || dims[1] <= 0 || dims[2] <= 0; }
  /// Linear offset of voxel (x, y, z): x fastest, then y, then z.
  std::size_t index(int x, int y, int z) const {
    return (std::size_t(z) * std::size_t(dims[1]) + std::size_t(y)) * std::size_t(dims[0]) +
           std::size_t(x);
  }
  /// index_T_world: grid-world [m] -> continuous index, (w - origin) / spacing per axis.
  Vec3 to_index(const Vec3& w) const {
    return {(w.x - origin_m.x) / spacing_m.x, (w.y - origin_m.y) / spacing_m.y,
            (w.z - origin_m.z) / spacing_m.z};
  }
  /// world_T_index: continuous index -> grid-world [m], origin + index * spacing per axis.
  Vec3 to_world(const Vec3& i) const {
    return {origin_m.x + i.x * spacing_m.x, origin_m.y + i.y * spacing_m.y,
            origin_m.z + i.z * spacing_m.z};
  }
  /// From the first to the last voxel centre [m].
  Vec3 extent_m() const {
    return {(dims[0] - 1) * spacing_m.x, (dims[1] - 1) * spacing_m.y,
            (dims[2] - 1) * spacing_m.z};
  }
  Vec3 centre_m() const { return origin_m + extent_m() * 0.5; }
};

}  // namespace isotouch::core
