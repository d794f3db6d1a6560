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
#include <string>

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

}  // namespace isotouch::service
