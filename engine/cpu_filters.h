// cpu_filters.h - CPU references of the filter passes (shaders/gaussian1d.comp,
// morph1d.comp, brick_minmax.comp): the same float operations in the same order (one
// thread, or the rows split among threads: each voxel's operations stay the same), so that
// GPU and CPU agree bit for bit on an IEEE device (this file is compiled
// with -ffp-contract=off: no FMA contraction).
#pragma once
#include "isotouch/engine/core_names.h"
#include <array>
#include <cstdint>
#include <vector>

#include "isotouch/engine/volume.h"

namespace isotouch::engine {

/// Normalised 1-D Gaussian kernel: 2r + 1 float weights, r = ceil(3 sigma_vox),
/// w[k + r] = exp(-k^2 / (2 sigma^2)) / sum_j exp(-j^2 / (2 sigma^2)) (computed in double,
/// then rounded to float once). sigma_vox <= 0 gives the identity kernel {1}.
/// @throws std::invalid_argument if sigma_vox is not finite or r would exceed kMaxRadius.
std::vector<float> gaussian_kernel(double sigma_vox);

/// Largest filter radius in voxels that a pass accepts (per side).
inline constexpr int kMaxFilterRadius = 64;

/// Per-axis Gaussian parameters of a volume: sigma in voxels = sigma_mm / spacing_mm.
struct GaussianAxes {
  std::array<double, 3> sigma_vox{};
  std::array<std::vector<float>, 3> kernel;  ///< gaussian_kernel(sigma_vox[a])
};
/// @throws std::invalid_argument if sigma_mm is not finite and > 0, or a kernel is too wide.
GaussianAxes gaussian_axes(const core::Grid& grid, double sigma_mm);

/// Per-axis box radius of the closing [voxels]: floor(radius_mm / spacing_mm + 1e-9), i.e.
/// every voxel whose centre lies within radius_mm of the centre along that axis.
/// @throws std::invalid_argument if radius_mm is not finite and >= 0, or too wide.
std::array<int, 3> closing_radii(const core::Grid& grid, double radius_mm);

/// One axis of the separable Gaussian with clamp-to-edge: out[i] = sum_k w[k+r] * in[clamp(i+k)].
/// `threads` > 1: the slices split among that many threads, the same bits (each voxel's
/// operations do not depend on the split).
void gaussian_axis_cpu(const std::vector<float>& in, std::vector<float>& out, const core::Grid& grid,
                       int axis, const std::vector<float>& kernel, unsigned threads = 1);
/// One axis of a box dilation (is_max) or erosion, radius r each side, clamp to edge;
/// NaN voxels are skipped (a window of only NaN gives -inf / +inf).
void morph_axis_cpu(const std::vector<float>& in, std::vector<float>& out, const core::Grid& grid, int axis,
                    int radius, bool is_max, unsigned threads = 1);

/// Separable Gaussian smoothing, x then y then z (sigma in mm, per-axis sigma in voxels).
Volume gaussian_cpu(const Volume& v, double sigma_mm);
/// Grayscale closing with a box structuring element of half-widths closing_radii():
/// dilation (max over x, y, z) then erosion (min over x, y, z).
Volume closing_cpu(const Volume& v, double radius_mm);

/// Value range of every 8^3 brick, widened by `halo` voxels each side (clamped).
struct BrickRanges {
  std::array<int, 3> bricks{0, 0, 0};  ///< ceil(dims / 8)
  int halo = 1;
  std::vector<float> min, max;         ///< one per brick, x fastest
  std::size_t count() const { return min.size(); }
};
/// `threads` > 1: the brick layers split among that many threads, the same bits.
BrickRanges brick_minmax_cpu(const Volume& v, int halo = 1, unsigned threads = 1);

}  // namespace isotouch::engine
