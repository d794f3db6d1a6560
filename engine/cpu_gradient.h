// cpu_gradient.h - CPU reference of the gradient pass (shaders/gradient.comp).
#pragma once
#include "isotouch/engine/core_names.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/engine/volume.h"

namespace isotouch::engine {

/// Reciprocal spacings as the GPU receives them (float), shared by both paths so
/// they perform the same float operations.
struct GradientConstants {
  float inv_2h[3];  ///< 1 / (2 spacing) [1/m]
  float inv_h[3];   ///< 1 / spacing [1/m]
};
GradientConstants gradient_constants(const core::Grid& grid);
/// Copies k's inverse spacings into a push-constant block with fields inv_2h_x .. inv_h_z
/// (DensePush, SparsePush: shaders/isotouch_shared.h).
template <class Push>
void set_inverse_spacings(Push& pc, const GradientConstants& k) {
  pc.inv_2h_x = k.inv_2h[0];
  pc.inv_2h_y = k.inv_2h[1];
  pc.inv_2h_z = k.inv_2h[2];
  pc.inv_h_x = k.inv_h[0];
  pc.inv_h_y = k.inv_h[1];
  pc.inv_h_z = k.inv_h[2];
}

/// Value and gradient per voxel: central differences in world units [value/m] inside,
/// one-sided differences at the borders, 0 along an axis of one voxel.
/// `threads` > 1: the slices split among that many threads, the same bits.
core::SampleField compute_samples_cpu(const Volume& volume, unsigned threads = 1);

}  // namespace isotouch::engine

namespace isotouch::engine {

/// Difference between two sample fields' gradients (GPU against CPU reference).
struct GradientDiff {
  double max_abs[3] = {0, 0, 0};  ///< per component [value/m]
  double max_abs_all = 0;         ///< over all components [value/m]
  double max_value_abs = 0;       ///< value channel
  double max_gradient_norm = 0;   ///< largest |gradient| in the reference [value/m]
  double max_rel = 0;             ///< max_abs_all / max_gradient_norm
  std::size_t nonfinite = 0;      ///< samples where either side is not finite
};
/// @throws std::invalid_argument if the grids differ.
GradientDiff compare_gradients(const core::SampleField& test, const core::SampleField& ref);

}  // namespace isotouch::engine
