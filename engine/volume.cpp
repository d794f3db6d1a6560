#include "isotouch/engine/volume.h"

#include <cmath>
#include <limits>

namespace isotouch::engine {

void Volume::update_stats() {
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  nan_voxels = inf_voxels = finite_voxels = 0;
  for (float v : voxels) {
    if (std::isnan(v)) {
      ++nan_voxels;
      continue;
    }
    if (std::isinf(v)) {
      ++inf_voxels;
      continue;
    }
    ++finite_voxels;
    lo = v < lo ? v : lo;
    hi = v > hi ? v : hi;
  }
  const float none = std::numeric_limits<float>::quiet_NaN();
  min_value = finite_voxels == 0 ? none : lo;
  max_value = finite_voxels == 0 ? none : hi;
}

core::Vec3 Volume::direction_apply(const core::Vec3& v) const {
  const auto& d = direction;
  return {d[0] * v.x + d[1] * v.y + d[2] * v.z, d[3] * v.x + d[4] * v.y + d[5] * v.z,
          d[6] * v.x + d[7] * v.y + d[8] * v.z};
}

core::Vec3 Volume::to_physical(const core::Vec3& g) const {
  return grid.origin_m + direction_apply(g - grid.origin_m);
}

core::Vec3 Volume::to_grid(const core::Vec3& p) const {
  const auto& d = direction;
  const core::Vec3 r = p - grid.origin_m;
  return grid.origin_m + core::Vec3{d[0] * r.x + d[3] * r.y + d[6] * r.z,
                                     d[1] * r.x + d[4] * r.y + d[7] * r.z,
                                     d[2] * r.x + d[5] * r.y + d[8] * r.z};
}

std::string Volume::orientation() const {
  static const char kPos[3] = {'L', 'P', 'S'}, kNeg[3] = {'R', 'A', 'I'};
  std::string code;
  for (int a = 0; a < 3; ++a) {  // column a of D: where index axis a points
    int best = 0;
    for (int r = 1; r < 3; ++r)
      if (std::abs(direction[std::size_t(r * 3 + a)]) > std::abs(direction[std::size_t(best * 3 + a)]))
        best = r;
    code += direction[std::size_t(best * 3 + a)] >= 0 ? kPos[best] : kNeg[best];
  }
  return code;
}

}  // namespace isotouch::engine
