#include "isotouch/sim/sim_device.h"

#include <algorithm>
#include <cmath>

namespace isotouch::sim {

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

int min_stable_substeps(const SimDeviceParams& p, double dt) {
  const double m = p.mass_kg, k = p.hand_stiffness_n_per_m;
  const double c = p.hand_damping_n_s_per_m + p.damping_n_s_per_m;
  if (!(m > 0 && std::isfinite(m) && dt > 0 && std::isfinite(dt) && k >= 0 && c >= 0 && std::isfinite(k) &&
        std::isfinite(c)))
    return kMaxSubsteps + 1;
  // Largest h with (k h^2 + 2 c h) / m <= 2: the positive root of k h^2 + 2 c h - 2 m,
  // written 2m / (c + sqrt(c^2 + 2km)) (no cancellation when c^2 >> km; m/c when k = 0).
  if (k == 0 && c == 0) return 1;  // free mass: any h
  const double h_max = 2.0 * m / (c + std::sqrt(c * c + 2.0 * k * m));
  if (!(h_max > 0)) return kMaxSubsteps + 1;
  const double n = std::ceil(dt / h_max);
  return n > double(kMaxSubsteps) ? kMaxSubsteps + 1 : std::max(1, int(n));
}

double min_stable_mass_kg(const SimDeviceParams& p, double dt, int substeps) {
  const double h = dt / std::max(1, substeps);
  const double c = p.hand_damping_n_s_per_m + p.damping_n_s_per_m;
  return 0.5 * (p.hand_stiffness_n_per_m * h * h + 2.0 * c * h);
}

void SimDevice::step(double dt, const Vec3& target, const Vec3& target_v) {
  if (dt != cached_dt_) {  // one sqrt per new period length, none per tick
    cached_dt_ = dt;
    cached_steps_ = std::min(kMaxSubsteps, std::max({1, p_.substeps, min_stable_substeps(p_, dt)}));
  }
  const int steps = cached_steps_;
  substeps_used_ = steps;
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

}  // namespace isotouch::sim
