// label_map.h - a label map IMAGE a client sent with its LBMETA (as 3D Slicer sends a
// segmentation's labelmap) as the materials of serve's session. Part of isotouch::service.
//
// The LBMETA names the label map IMAGE (each element's DeviceName) and gives, per element,
// one material: its name, its label value (the voxel value that marks it) and its colour
// (RGBA). The IMAGE must lie on the session volume's grid: the same dimensions, and the same
// spacing, origin and direction within the tolerances below (no resampling). Every non-zero
// voxel value must be one of the LBMETA's labels; 0 is no material.
#pragma once
#include <string>
#include <vector>

#include "isotouch/engine/volume.h"
#include "isotouch/materials/label_volume.h"
#include "isotouch/service/igtl_message.h"

namespace isotouch::service {

/// Spacing: relative difference at most this (the IMAGE's spacing is float32 mm).
inline constexpr double kLabelSpacingTolerance = 1e-4;
/// Origin: at most this fraction of the volume's smallest spacing apart, per axis.
inline constexpr double kLabelOriginTolerance = 1e-2;
/// Direction: each of the 9 cosines at most this apart (volume_from_image's unit tolerance).
inline constexpr double kLabelDirectionTolerance = 1e-3;

/// The materials of `labels` (label_map_from_image's volume of the IMAGE `device`) with the
/// elements `meta` of its LBMETA, on `frame`'s grid (the session's volume: its voxels are not
/// read). Material i (id i + 1) is meta[i]: its name, label value and colour (RGB / 255). A
/// material of `scene` (the scene's materials section) of the same name lends it every other
/// field (K, friction, rate, density_scale, critical, margin); a note says so.
/// @throws engine::VolumeError, "igtl:DEVICE: ...", naming the field and both values: another
///         grid (dimensions, spacing along an axis, origin along an axis [mm, LPS], a
///         direction cosine); a voxel value that no LBMETA element names (the value and its
///         voxel); an element of label value 0 (the background), two elements of one value or
///         one name; no element.
materials::LabelVolume labels_from_image(const engine::Volume& labels, const std::string& device,
                                         const std::vector<LabelMetaEntry>& meta, const engine::Volume& frame,
                                         const std::vector<materials::Material>& scene);

/// "skull (label 1, colour #e6dcc8, 1200 voxels, critical), ...": each material of `lv`.
std::string describe_materials(const materials::LabelVolume& lv);

}  // namespace isotouch::service
