// workspace.h - the map from device space to the volume's world space.
#pragma once
#include "isotouch/servo/core_names.h"
#include "isotouch/core/vec3.h"

namespace isotouch::servo {

/// world_T_device: world [m] = scale * device [m] + translation [m]. Axes are shared
/// (no rotation), so a force in world axes is a force in device axes.
struct WorkspaceTransform {
  double scale = 1.0;   ///< world metres per device metre
  Vec3 translation_m;   ///< world position of the device origin [m]
  Vec3 to_world(const Vec3& device_m) const { return device_m * scale + translation_m; }
  Vec3 to_device(const Vec3& world_m) const { return (world_m - translation_m) / scale; }
};

}  // namespace isotouch::servo
