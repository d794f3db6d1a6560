// label_export.h - the edited label map for 3D Slicer: the labels of a labelled scene after
// the drill (or any brush) removed voxels, written as a `.seg.nrrd` whose segments carry the
// materials' names, label values and colours (the SegmentN_ keys seg_nrrd.h reads), so that
// 3D Slicer and this project's own reader (load_label_volume) load it.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/volume.h"
#include "isotouch/materials/material.h"

namespace isotouch::materials {

/// A voxel's label after edits: 0 (background) where an edit removed it, i.e. it was inside
/// `iso` before and is not after (a drilled voxel); else its label as it was. A voxel outside
/// `iso` from the start (a material below the isovalue, such as a tooth's pulp) keeps its label.
inline std::uint8_t edited_id(std::uint8_t id, float before, float after, const core::Isosurface& iso) {
  return iso.contains(before) && !iso.contains(after) ? std::uint8_t(0) : id;
}

/// edited_id of every voxel. @throws MaterialError when the three sizes differ.
std::vector<std::uint8_t> edited_ids(const std::vector<std::uint8_t>& ids, const std::vector<float>& before,
                                     const std::vector<float>& after, const core::Isosurface& iso);

/// The label value each material (id = index + 1) is written with: its own label value (a
/// label map's, a `.seg.nrrd` segment's) when every material has one, distinct, else its id
/// (a transfer function's materials have none).
std::vector<int> export_label_values(const std::vector<Material>& materials);

/// Writes `ids` (one material id per voxel of `geometry`'s grid, x fastest: 0 background,
/// i = materials[i - 1]) as a 3D Slicer segmentation: NRRD0004, gzip, LPS `space`, the
/// volume's origin and direction x spacing (mm), voxels the export_label_values (unsigned char,
/// unsigned short above 255), and per material a segment N = id - 1 with SegmentN_Name,
/// _LabelValue, _Layer (0), _Color, _ID, _Extent. Written whole or not at all (io::write_output).
/// @throws MaterialError naming the path and the field: ids of another size than the grid,
///         an id above materials.size(), a material name with a line break (a header line),
///         or the file that cannot be written.
void write_seg_nrrd(const std::string& path, const std::vector<std::uint8_t>& ids, const std::vector<Material>& materials,
                    const engine::Volume& geometry);

}  // namespace isotouch::materials
