// bench_peers.h - the libraries a user would otherwise pick for `bench engine`'s dense chain,
// timed on the same volume and cores: ITK DiscreteGaussianImageFilter + GradientImageFilter
// (+ packing value and gradient into one 16-byte sample per voxel), and OpenVDB
// tools::copyFromDense + tools::gradient (TBB). The ITK and OpenVDB headers are included by
// bench_peers.cpp only.
#pragma once
#include <limits>
#include <string>

#include "isotouch/engine/volume.h"

namespace isotouch::bench {

/// One run of every peer at one thread count; wall times [ms], NaN where not available.
struct PeerTimes {
  double itk_gaussian_ms = std::numeric_limits<double>::quiet_NaN();
  double itk_gradient_ms = std::numeric_limits<double>::quiet_NaN();
  double itk_pack_ms = std::numeric_limits<double>::quiet_NaN();      ///< interleave into vec4 samples
  double vdb_from_dense_ms = std::numeric_limits<double>::quiet_NaN();  ///< copyFromDense (tolerance 0)
  double vdb_gradient_ms = std::numeric_limits<double>::quiet_NaN();    ///< tools::gradient (Vec3SGrid)
  std::string itk_why, vdb_why;  ///< why a peer is missing (empty: measured)
};

/// Runs ITK's Gaussian (variance sigma_mm^2 in physical units, the image spacing in mm) and
/// gradient, and OpenVDB's copyFromDense + gradient of the Gaussian's output, each limited to
/// `threads` threads (ITK: the filters' and the global multithreader's maximum; OpenVDB:
/// tbb::global_control). Exceptions are reported in *_why.
PeerTimes run_peers_once(const engine::Volume& v, double sigma_mm, int threads);

}  // namespace isotouch::bench
