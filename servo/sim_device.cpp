#include "sim_device.h"

#include <algorithm>

namespace isotouch::servo {

void SimDevice::step(double dt, const Vec3& target, const Vec3& target_v) {
  const int steps = std::max(1, p_.substeps);
  const double h = dt / steps;
  for (int i = 0; i < steps; ++i) {
    // The hand target moves linearly inside the period.
    const Vec3 tgt = target + target_v * (h * (i + 1) - dt);
    const Vec3 f = f_cmd_ + hand_force(tgt, target_v) - v_ * p_.damping_n_s_per_m;
    v_ += f * (h / p_.mass_kg);
    x_ += v_ * h;
  }
}

}  // namespace isotouch::servo
