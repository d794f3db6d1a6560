// brick_field.h - the sparse (bricked) published snapshot (issue 8, items 4 and 5).
// Part of isotouch::core, header-only. OWNER: core-bricks helper (this is the contract the
// engine writes to; the owner fills in the builder, the compact formats and FieldView's
// bricked mode).
//
// Layout
// - The grid is cut into bricks of kBrickSize^3 voxels (OpenVDB's leaf size), brick
//   (bx, by, bz) holding voxels [8 bx, 8 bx + 8) x ... ; bricks counted ceil(dims / 8) per
//   axis, linear brick id = (bz * nby + by) * nbx + bx (x fastest).
// - An *active* brick (its value range, widened by the 1-voxel halo the gradient and the
//   trilinear cell need, straddles the isovalue) stores kBrickStored^3 = 9^3 samples: the
//   brick plus one voxel on the high side of every axis, so every trilinear cell whose
//   lower corner lies in the brick is read from that one brick (one table lookup per cell).
//   Local sample (i, j, k), i, j, k in 0..8, is voxel (8 bx + i, 8 by + j, 8 bz + k), local
//   order x fastest: i + 9 j + 81 k. Positions beyond the grid are never read (fill them
//   with the background value and a zero gradient).
// - Every other brick is *uniform*: entirely inside or entirely outside the isosurface. It
//   stores no samples, only its tile value (see tile_value()): every voxel in it reads
//   {tile, 0, 0, 0}.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "grid.h"
#include "isosurface.h"
#include "sample_field.h"

namespace isotouch::core {

inline constexpr int kBrickSize = 8;                      ///< voxels per brick edge
inline constexpr int kBrickStored = kBrickSize + 1;       ///< stored samples per edge (+1 apron)
inline constexpr int kBrickSamples = kBrickStored * kBrickStored * kBrickStored;  ///< 729

/// How the samples of active bricks are stored (item 5).
enum class SampleFormat : std::uint8_t {
  kFp32,     ///< core::Sample, 16 B per sample
  kFp16,     ///< value + gradient as IEEE half, 8 B per sample
  kUnorm16,  ///< per-brick normalized 16-bit integers, 8 B per sample
};

/// Bricks per axis of `g`: ceil(dims / 8).
inline std::array<int, 3> brick_counts(const Grid& g) {
  return {(g.dims[0] + kBrickSize - 1) / kBrickSize, (g.dims[1] + kBrickSize - 1) / kBrickSize,
          (g.dims[2] + kBrickSize - 1) / kBrickSize};
}

/// The tile value of a brick whose (halo-widened) value range [lo, hi] does not straddle
/// `iso`: the bound of the range nearest tau (kAbove: lo if lo > tau (inside), hi if
/// hi <= tau (outside); kBelow mirrored), so the brick reads as the same side of the
/// surface as all its voxels. Returns false if the range straddles (the brick is active).
/// A range with no finite value (lo > hi: only NaN voxels) is uniform outside with tile
/// = NaN... callers pass `background` for it.
inline bool tile_value(float lo, float hi, const Isosurface& iso, float background, float& tile) {
  if (lo > hi) {
    tile = background;
    return true;
  }
  const double t = iso.tau;
  if (iso.inside == InsideIs::kAbove) {
    if (lo > t) { tile = lo; return true; }
    if (hi <= t) { tile = hi; return true; }
  } else {
    if (hi < t) { tile = hi; return true; }
    if (lo >= t) { tile = lo; return true; }
  }
  return false;
}

/// What an engine (GPU sparse chain, CPU reference, or dense-to-bricks conversion) hands
/// over to be published as a bricked SampleField: the active bricks' fp32 samples and the
/// uniform bricks' tile values.
struct BrickedInput {
  Grid grid;
  float background = 0.0f;                  ///< value outside the grid (SampleField::background)
  std::vector<std::uint32_t> active;        ///< linear ids of active bricks, ascending
  std::vector<Sample> pool;                 ///< active.size() * kBrickSamples fp32 samples
  std::vector<float> tile;                  ///< one per brick (all bricks); ignored for active ones
};

}  // namespace isotouch::core
