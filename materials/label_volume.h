// label_volume.h - the material of every voxel of a scan, on the scan's own grid: from a
// label map beside the scan (NIfTI or NRRD, TotalSegmentator's form), from 3D Slicer's
// `.seg.nrrd` (its segments' names, label values and colours), or from a haptic transfer
// function on the scan's values (value ranges -> material).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "isotouch/core/grid.h"
#include "isotouch/engine/volume.h"
#include "isotouch/materials/material.h"

namespace isotouch::materials {

/// Most materials one scene names (ids are one byte; 0 is "none").
inline constexpr std::size_t kMaxMaterials = 255;

/// One material id per voxel of the scan's grid.
struct LabelVolume {
  core::Grid grid;                    ///< the scan's grid (grid-world frame [m])
  std::vector<std::uint8_t> ids;      ///< grid.voxel_count() ids, x fastest: 0 none, i = materials[i - 1]
  std::vector<Material> materials;    ///< the scene's list, label values and colours filled in
  std::vector<std::size_t> voxels;    ///< voxels per id, materials.size() + 1 entries (0: none)
  std::string source;                 ///< "label map PATH", "3D Slicer segmentation PATH", "transfer function"
  std::vector<std::string> notes;     ///< for the log, e.g. that the labels were resampled

  std::uint8_t at(int x, int y, int z) const { return ids[grid.index(x, y, z)]; }
};

/// The labels `spec` describes, on `scan`'s grid. A label map on another grid (dims,
/// spacing, origin or direction differ) is resampled onto the scan's: each scan voxel takes
/// the label of the label map's voxel nearest its physical position (0 outside the map),
/// and a note says so. A material no voxel holds is a note too.
/// @throws MaterialError naming the file, the field or header key, and the value: a label
///         map voxel that is not a whole number in [0, 65535] (its position and voxel type),
///         a label value in the map that no material claims, a `.seg.nrrd` whose header
///         lacks a segment key (seg_nrrd.h), a material with no segment of its name, a label
///         map whose box holds no voxel of the scan (grid mismatch), more than kMaxMaterials
///         materials. engine::VolumeError from io::load_volume (an unreadable file).
LabelVolume load_label_volume(const MaterialsSpec& spec, const engine::Volume& scan);

}  // namespace isotouch::materials
