// material_cut.h - per-material drilling: the material id of every voxel and, per id, how
// fast the drill removes it and whether it must never be removed (a critical structure).
// Plain data (no dependency on the materials library): the run fills it from the scene's
// label volume (materials/label_volume.h), tests from labels of their own.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace isotouch::session {

/// How the drill treats one material.
struct CutMaterial {
  double rate = -1;           ///< [value units / (N s)] at density factor 1 (Brush::rate's unit); < 0: the brush's
  double density_scale = 0;   ///< [value units]; 0 = the brush's own targets.density_scale
  bool critical = false;      ///< never changed: its voxels keep their value under every brush (drill, carve, add, smooth)
};

/// The label of every voxel of the edited volume's grid and the per-label cut.
struct MaterialCut {
  std::vector<std::uint8_t> ids;     ///< one per voxel, x fastest: 0 = no material (the brush's own rate), i = table[i - 1]; past the table: left unchanged
  std::vector<CutMaterial> table;    ///< per material id - 1
};

/// Empty if `cut` fits a volume of `voxels` voxels and its numbers are usable, else the
/// reason naming the field and the value.
std::string validate(const MaterialCut& cut, std::size_t voxels);

}  // namespace isotouch::session
