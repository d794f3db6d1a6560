#include "volume.h"

#include <cmath>
#include <limits>

namespace isotouch::engine {

void Volume::update_stats() {
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  nan_voxels = 0;
  for (float v : voxels) {
    if (!std::isfinite(v)) {
      ++nan_voxels;
      continue;
    }
    lo = v < lo ? v : lo;
    hi = v > hi ? v : hi;
  }
  min_value = nan_voxels == voxels.size() ? 0.f : lo;
  max_value = nan_voxels == voxels.size() ? 0.f : hi;
}

}  // namespace isotouch::engine
