#include "sim_device.h"

#include <algorithm>
#include <cmath>

namespace isotouch::servo {

Vec3 SimDevice::position() const {
  const double q = p_.encoder_resolution_m;
  if (!(q > 0)) return x_;
  return {std::round(x_.x / q) * q, std::round(x_.y / q) * q, std::round(x_.z / q) * q};
}

void SimDevice::command_force(const Vec3& f) {
  if (!finite(f)) {
    f_cmd_ = {};
    ++refused_;
    return;
  }
  f_cmd_ = f;
  if (saturate(f_cmd_, p_.force_max_n)) ++saturated_;
}

void SimDevice::step(double dt, const Vec3& target, const Vec3& target_v) {
  const int steps = std::max(1, p_.substeps);
  const double h = dt / steps;
  const double fc = p_.coulomb_friction_n;
  for (int i = 0; i < steps; ++i) {
    // The hand target moves linearly inside the period.
    const Vec3 tgt = target + target_v * (h * (i + 1) - dt);
    const Vec3 f_other = f_cmd_ + hand_force(tgt, target_v) - v_ * p_.damping_n_s_per_m;
    Vec3 v_new;
    if (fc > 0) {
      // Coulomb friction: sticks while the other forces stay below fc, else opposes motion.
      const double speed = norm(v_);
      if (speed < 1e-9 && norm(f_other) <= fc) {
        v_new = {};
      } else {
        const Vec3 dir = speed >= 1e-9 ? v_ / speed : f_other / norm(f_other);  // impending motion
        v_new = v_ + (f_other - dir * fc) * (h / p_.mass_kg);
        if (speed >= 1e-9 && dot(v_new, v_) < 0) v_new = {};  // friction stops, never reverses
      }
    } else {
      v_new = v_ + f_other * (h / p_.mass_kg);
    }
    const Vec3 dx = v_new * h;
    rendered_work_ += dot(f_cmd_, dx);
    damping_loss_ += p_.damping_n_s_per_m * dot(v_new, v_new) * h;
    v_ = v_new;
    x_ += dx;
  }
}

}  // namespace isotouch::servo
