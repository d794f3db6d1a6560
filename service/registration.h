// registration.h - the rigid registration of a tracker to the image, for `isotouch serve`'s
// TRANSFORM stream: PLUS users register the tracker to the image with a rigid transform
// (TrackerToImage), not a translation. Part of isotouch::service.
//
// Frames: both in RAS [mm]; the tracker's (the stream's poses, the forces a PLUS device
// applies) and the image's (the volume received or loaded, Slicer's scene).
//   pose:  p_image = R p_tracker + t     [mm]
//   force: f_tracker = R^T f_image       [N] (a rotation's inverse; the translation does not act)
#pragma once
#include <array>
#include <string>

#include "isotouch/core/vec3.h"

namespace isotouch::service {

struct Registration {
  /// Rotation, row-major (r[3 * row + col]); a proper rotation (orthonormal, det +1).
  std::array<double, 9> r{1, 0, 0, 0, 1, 0, 0, 0, 1};
  core::Vec3 t_mm;  ///< translation [mm, image RAS]

  /// A tracker point [mm, RAS] in the image [mm, RAS]: R p + t.
  core::Vec3 to_image_mm(const core::Vec3& p) const {
    return {r[0] * p.x + r[1] * p.y + r[2] * p.z + t_mm.x, r[3] * p.x + r[4] * p.y + r[5] * p.z + t_mm.y,
            r[6] * p.x + r[7] * p.y + r[8] * p.z + t_mm.z};
  }
  /// An image vector (a force [N, RAS]) in the tracker's frame: R^T f.
  core::Vec3 to_tracker(const core::Vec3& f) const {
    return {r[0] * f.x + r[3] * f.y + r[6] * f.z, r[1] * f.x + r[4] * f.y + r[7] * f.z,
            r[2] * f.x + r[5] * f.y + r[8] * f.z};
  }
  bool is_identity() const;
  /// "rotation [[a b c] [d e f] [g h i]], translation (x, y, z) mm".
  std::string describe() const;
};

/// A 4x4 (row-major, OpenIGTLink's Matrix4x4 layout: m[row][col], translation in column 3
/// [mm]) as a registration. @throws std::invalid_argument naming why unless the upper 3x3
/// is a rotation (R^T R = I within 1e-3, det within 1e-3 of +1: no scale, shear or mirror),
/// the last row 0 0 0 1 and every entry finite.
Registration registration_from_matrix(const double m[4][4]);

/// Reads a registration from a text file: 16 numbers, the 4x4 row by row (separated by
/// spaces, commas or new lines; lines from '#' on are comments), or 12 (the last row
/// 0 0 0 1 left out). @throws std::runtime_error naming the file when it cannot be read or
/// holds another count of numbers; as registration_from_matrix.
Registration load_registration(const std::string& path);

}  // namespace isotouch::service
