// image_volume.h - an OpenIGTLink IMAGE as an isotouch volume. Part of isotouch::service.
//
// The IMAGE header carries the voxel size, the unit direction of each index axis and the
// position of the image's CENTRE (the middle between its first and last voxel centres, as
// OpenIGTLink and 3D Slicer define it), in the coordinate system it names (RAS or LPS), in
// mm. isotouch's volumes are LPS in metres with the origin at voxel (0,0,0) (engine/volume.h),
// so an image sent from a file lands where loading that file puts it:
//   origin_LPS [m] = F (centre - D (spacing * (dims - 1) / 2)) * 1e-3,
//   direction_LPS  = F D,   F = diag(-1, -1, 1) for RAS, identity for LPS.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <igtlImageMessage.h>

#include "isotouch/engine/volume.h"

namespace isotouch::service {

/// The volume an unpacked IMAGE holds (reader "igtl:IMAGE", path "igtl:" + its device
/// name). Refuses, with engine::VolumeError naming the field and value: a single slice or
/// any axis under 2 voxels, a sub-volume (only whole images), more than one component, a
/// label map (device name containing "label", any case), sizes past io's volume limits
/// (io/volume_io.h), a spacing that is not finite and positive, direction columns that are
/// not unit and perpendicular within 1e-3, a centre that is not finite.
engine::Volume volume_from_image(igtl::ImageMessage& image);

/// A label map IMAGE (one a LBMETA named) read as volume_from_image reads an image, its
/// voxels the label values (whole numbers as sent), whatever its device name. Refuses, with
/// engine::VolumeError naming the field and value, what volume_from_image refuses (but the
/// name) and a float scalar type (label maps are integer images).
engine::Volume label_map_from_image(igtl::ImageMessage& image);

/// A box of voxels [lo, hi) in index space.
struct VoxelBox {
  std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
  bool empty() const { return hi[0] <= lo[0] || hi[1] <= lo[1] || hi[2] <= lo[2]; }
  /// Grows to hold `o`.
  void add(const VoxelBox& o);
};

/// The IMAGE named `device` that volume_from_image reads back as `v`: float32 voxels, RAS,
/// the position the image's centre [mm]. With `box` not empty, only the voxels of `box`
/// (the IMAGE's sub-volume fields: offset box.lo, size box.hi - box.lo; the dimensions,
/// spacing, directions and centre still the whole image's); else the whole image. Time
/// stamped now, packed for sending. `box` must lie inside the volume.
std::vector<std::uint8_t> pack_image(const engine::Volume& v, const std::string& device, const VoxelBox& box);
/// As pack_image(), the voxels of `box` (not empty, inside the volume) written by `fill` into
/// the IMAGE's buffer (x fastest, then y, then z, box.hi - box.lo of each); `frame`'s voxels
/// are not read (its grid and direction place the image).
std::vector<std::uint8_t> pack_image(const engine::Volume& frame, const std::string& device, const VoxelBox& box,
                                     const std::function<void(float* out)>& fill);

}  // namespace isotouch::service
