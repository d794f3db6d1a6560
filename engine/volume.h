// volume.h - a scalar volume as loaded from disk or made synthetically.
#pragma once
#include "isotouch/engine/core_names.h"
#include <array>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/core/sample_field.h"

namespace isotouch::engine {

/// A loading or validation problem. what() names the file and the problem.
struct VolumeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Scalar volume on a regular grid. Voxels are float, x fastest, then y, then z.
///
/// Two frames (both in metres):
/// - the *grid frame*, index-aligned, in which the servo works:
///   grid [m] = origin + index * spacing, per axis (`grid.to_world`);
/// - the *physical frame* of the file (ITK's convention, LPS for medical images):
///   physical [m] = origin + D (spacing * index), with D = `direction`, whose column a
///   is the physical unit direction of increasing index a.
/// Both frames share the origin (voxel (0,0,0)); they coincide when D is identity.
/// Every point reported to a user must be in the physical frame: use `to_physical`
/// for points and `direction_apply` for free vectors (forces, normals, gradients).
struct Volume {
  core::Grid grid;
  std::vector<float> voxels;          ///< grid.voxel_count() values, in file units
  std::string path;                   ///< where it came from ("synthetic:..." otherwise)
  std::string reader;                 ///< "itk:MetaImageIO", "teem:nrrdLoad", "synthetic"
  std::string component_type;         ///< on-disk type, e.g. "short", "unsigned_short"
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< D, row-major 3x3
  bool direction_is_identity = true;
  float min_value = 0, max_value = 0; ///< over finite voxels; NaN when there is none
  std::size_t nan_voxels = 0;         ///< voxels that are NaN
  std::size_t inf_voxels = 0;         ///< voxels that are +Inf or -Inf
  std::size_t finite_voxels = 0;      ///< voxels that are finite

  /// Recompute min/max and the NaN/Inf/finite counts from voxels.
  void update_stats();

  /// Non-finite voxels (NaN + Inf).
  std::size_t nonfinite_voxels() const { return nan_voxels + inf_voxels; }

  /// Grid frame point [m] -> physical frame point [m]: origin + D (g - origin).
  core::Vec3 to_physical(const core::Vec3& grid_world_m) const;
  /// Physical frame point [m] -> grid frame point [m]: origin + D^T (p - origin)
  /// (D is orthonormal for every format we read).
  core::Vec3 to_grid(const core::Vec3& physical_m) const;
  /// Grid frame vector -> physical frame vector: D v (forces [N], normals, gradients).
  core::Vec3 direction_apply(const core::Vec3& v) const;
  /// Physical position [m] of a (continuous) voxel index: origin + D (spacing * index).
  core::Vec3 index_to_physical(const core::Vec3& index) const {
    return to_physical(grid.to_world(index));
  }

  /// Three-letter orientation code: for index axes x, y, z in turn, the physical
  /// direction that axis mostly points toward (largest |component| of D's column),
  /// in ITK's LPS physical frame: +x = L, -x = R, +y = P, -y = A, +z = S, -z = I.
  /// Identity D gives "LPS"; a standard RAS NIfTI (ITK flips x and y) gives "RAS";
  /// a radiological (x-flipped) one gives "LAS". This is the "points toward" convention
  /// of nibabel's aff2axcodes and of ITK's AnatomicalOrientation::PositiveEnum.
  std::string orientation() const;
};

}  // namespace isotouch::engine
