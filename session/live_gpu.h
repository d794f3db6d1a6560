// live_gpu.h - the live field's GPU recompute (session/live_field.h), behind a seam so that
// the session library holds no Vulkan code (gpu_parts.h): live_gpu.cpp (isotouch::session_gpu)
// runs engine::SparseFilter (the sparse chain's list kernels); live_gpu_none.cpp, its
// stand-in without Vulkan (ISOTOUCH_BUILD_ENGINE=OFF), says that this build has no Vulkan.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/result.h"
#include "isotouch/engine/volume.h"
#include "isotouch/session/gpu_parts.h"

namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch::session {

/// The filter stage of the sparse chain's list strategy on chosen candidate bricks of a
/// volume kept on the device (engine::SparseFilter).
class LiveGpuFilter {
 public:
  virtual ~LiveGpuFilter() = default;
  /// Bricks `bricks` of `voxels` (the whole volume) into the device's copy.
  virtual void set_bricks(const float* voxels, const std::vector<std::uint32_t>& bricks) noexcept = 0;
  /// The filters on the candidates' extents: the last filter's output, dense-addressed,
  /// exact at voxels 8 b - 1 .. 8 b + 9 of every candidate b. `submit_ms`: submit to fence.
  /// @throws engine::VolumeError on a resource problem.
  virtual const float* filter(const std::vector<std::uint32_t>& candidates, double& submit_ms) = 0;
  virtual std::string describe() const = 0;
};

// make_live_gpu_filter(ctx, vol, passes) (gpu_parts.h): an error (no throw) where this build
// has no Vulkan, the pass list has no filter, or the device cannot run the kernels.

}  // namespace isotouch::session
