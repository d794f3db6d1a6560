// pass_check.h - `isotouch check VOLUME`: the gradient pass on the GPU against its CPU
// reference, with the volume's header figures; `check --all VOLUME [--scene S]`: every engine
// pass on the GPU against its one-thread CPU reference, and the gradient against OpenVDB's
// central differences as an independent reference.
#pragma once
#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "isotouch/engine/volume.h"

namespace isotouch::bench {

/// Loads `path` (any volume format or a DICOM folder), runs the gradient pass on the Vulkan
/// device `device` (z-slabs when `slab_mib` > 0 is below the binding limit) and the CPU
/// reference, prints the volume's dims, spacing, orientation, value range, non-finite voxels
/// and the largest GPU-CPU difference. @return 0 within 1e-6 relative on finite data, 3
/// otherwise (the FAIL line says why); throws on a bad file (named) or a Vulkan set-up error.
int run_check_gradient(const std::string& path, const std::string& device, double slab_mib, std::ostream& out);

struct CheckAllOptions {
  std::string volume_path;       ///< volume file; ignored if scene_path is set
  std::string scene_path;        ///< scene JSON: its volume (file or synthetic) and isovalue
  std::string device;            ///< Vulkan device (name substring or index; empty: default)
  double max_binding_mib = 0;    ///< > 0: smaller storage-binding limit (forces z-slabs)
  bool validation = false;       ///< validation layer on (also with ISOTOUCH_VALIDATION=1)
  /// Debug (hidden option): move the first value of the CPU Gaussian reference 1000 ULP up, to
  /// prove that the comparison fails. Never use it for a real check.
  bool inject_mismatch = false;
};

/// Runs gaussian(1 mm), closing(1 mm), gradient, brick_minmax(halo 1) each on its own and
/// then as one chain, GPU against CPU; prints a table (max abs and relative difference, ULP
/// max / p99 / count of non-identical values, NaN/Inf counts, GPU and CPU time) and a verdict.
/// Pass rule: bit identity on a CPU Vulkan device (lavapipe: same float operations in the
/// same order); at most kUlpBoundOtherDevice ULPs elsewhere; no NaN/Inf in any output; no
/// non-finite input voxel; no validation message when the layer is on; OpenVDB within
/// kUlpBoundOpenVdb ULPs on interior voxels.
/// @return 0 pass, 3 disagreement (the FAIL line says which), throws on bad input
///         (volume/scene errors name file, field and value; Vulkan set-up errors).
int run_check_all(const CheckAllOptions& options, std::ostream& out);

/// ULPs allowed between GPU and CPU on a device that is not a CPU (FMA contraction and
/// reassociation by the driver's compiler).
inline constexpr std::uint64_t kUlpBoundOtherDevice = 64;
/// ULPs allowed between our central differences (hi - lo) * float(1 / 2h) and OpenVDB's
/// Gradient<ScaleMap, CD_2ND> ((hi - lo) * double(1 / 2h), rounded to float): two roundings
/// of the reciprocal and of the product, at most 1 ULP each.
inline constexpr std::uint64_t kUlpBoundOpenVdb = 2;

/// OpenVDB's gradient of a volume (bench/openvdb_check.cpp, the one translation unit that
/// includes OpenVDB): a FloatGrid copy of the voxels with a ScaleMap of the spacing [m],
/// math::Gradient<ScaleMap, CD_2ND> at every voxel at least one voxel from every border.
struct OpenVdbGradient {
  bool available = false;   ///< false if built without OpenVDB (libopenvdb-dev)
  std::string version;      ///< e.g. "10.0.1"
  std::vector<float> g;     ///< 3 per interior voxel (gx, gy, gz) [value/m], grid frame
  std::vector<std::size_t> voxel;  ///< the voxel index (x fastest) of each interior voxel
  double ms = 0;            ///< wall time of the copy and the gradient
};
OpenVdbGradient openvdb_gradient(const engine::Volume& volume);

}  // namespace isotouch::bench
