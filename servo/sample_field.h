// sample_field.h - the plane-ready sample format. servo/ owns it; engine/ writes it.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "vec3.h"

namespace isotouch::servo {

/// One sample per voxel: the scalar value and its gradient.
/// Layout = GLSL `vec4(value, gx, gy, gz)` written by shaders/gradient.comp (16 bytes,
/// pinned by static_assert in engine/gpu_layout.cpp).
struct Sample {
  float value;  ///< scalar value (scanner units, HU, or signed distance [m])
  float gx;     ///< d value / dx [value units / m], volume frame
  float gy;     ///< d value / dy
  float gz;     ///< d value / dz
};
static_assert(sizeof(Sample) == 16, "Sample must match GLSL vec4");

/// Regular grid: world [m] = origin_m + index * spacing_m, per axis (the volume frame).
/// Index space has voxel centres at integer coordinates.
struct Grid {
  std::array<int, 3> dims{0, 0, 0};      ///< voxels along x, y, z
  Vec3 spacing_m{1e-3, 1e-3, 1e-3};      ///< voxel size [m]
  Vec3 origin_m{0, 0, 0};                ///< world position of voxel (0,0,0) centre [m]

  std::size_t voxel_count() const {
    return std::size_t(dims[0]) * std::size_t(dims[1]) * std::size_t(dims[2]);
  }
  std::size_t index(int x, int y, int z) const {
    return (std::size_t(z) * std::size_t(dims[1]) + std::size_t(y)) * std::size_t(dims[0]) +
           std::size_t(x);
  }
  /// World [m] -> continuous index coordinates.
  Vec3 to_index(const Vec3& w) const {
    return {(w.x - origin_m.x) / spacing_m.x, (w.y - origin_m.y) / spacing_m.y,
            (w.z - origin_m.z) / spacing_m.z};
  }
  /// Continuous index -> world [m].
  Vec3 to_world(const Vec3& i) const {
    return {origin_m.x + i.x * spacing_m.x, origin_m.y + i.y * spacing_m.y,
            origin_m.z + i.z * spacing_m.z};
  }
  Vec3 extent_m() const {
    return {(dims[0] - 1) * spacing_m.x, (dims[1] - 1) * spacing_m.y,
            (dims[2] - 1) * spacing_m.z};
  }
  Vec3 centre_m() const { return origin_m + extent_m() * 0.5; }
};

/// The sample field the servo reads: one Sample per voxel, x fastest, then y, then z.
/// Immutable once published (engine/ publishes a new one after each edit).
struct SampleField {
  Grid grid;
  std::vector<Sample> samples;  ///< grid.voxel_count() entries
  std::uint64_t version = 0;    ///< increases with every publication
};

}  // namespace isotouch::servo
