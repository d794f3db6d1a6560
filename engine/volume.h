// volume.h - a scalar volume as loaded from disk or made synthetically.
#pragma once
#include <array>
#include <stdexcept>
#include <string>
#include <vector>

#include "sample_field.h"

namespace isotouch::engine {

/// A loading or validation problem. what() names the file and the problem.
struct VolumeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Scalar volume on a regular grid. Voxels are float, x fastest, then y, then z.
/// The world frame is the grid frame: world [m] = origin + index * spacing per axis.
/// The file's direction cosines are kept in `direction` (row-major 3x3) but not applied;
/// `direction_is_identity` says whether the two frames coincide.
struct Volume {
  servo::Grid grid;
  std::vector<float> voxels;          ///< grid.voxel_count() values, in file units
  std::string path;                   ///< where it came from ("synthetic:..." otherwise)
  std::string reader;                 ///< "itk:MetaImageIO", "teem:nrrdLoad", "synthetic"
  std::string component_type;         ///< on-disk type, e.g. "short", "unsigned_short"
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};
  bool direction_is_identity = true;
  float min_value = 0, max_value = 0; ///< over finite voxels
  std::size_t nan_voxels = 0;         ///< non-finite voxels found

  /// Recompute min/max/nan_voxels from voxels.
  void update_stats();
};

}  // namespace isotouch::engine
