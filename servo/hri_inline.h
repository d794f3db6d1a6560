// hri_inline.h - HriRenderer's pieces that the ticks of more than one of servo/hri*.cpp
// inline; internal to those files (the renderer's API is hri.h). They are defined here,
// not in one .cpp, because the servo's common ticks are fast only with them inlined: a call
// where they are inlined today adds its cost to every tick.
// - eqs. 2 and 3 (contact_force): VHIP = HIP + ((p - HIP) . N) N (eq. 2) and the
//   spring-damper force (eq. 3) with the physical sign, F = -K d - B v_d, for both
//   variants: the paper's with its recovery (§3.3: an embedded update ramped upward over
//   recovery_time_s), force shading (§3.3) and friction (§3.1); the robust variant's
//   frictionless tick in scalar form (no square root) and its recovery ramp (robust_ramp,
//   hri_robust.cpp).
// - The robust tick's force limit (limit_force), velocity filter (filter_velocity: the
//   measured period, a first-order low-pass; the paper's backward difference at the nominal
//   period gave damping spikes after lost ticks) and the long-step test (long_step: when a
//   segment is worth marching for a thin wall).
#pragma once

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>

#include "isotouch/servo/sampling.h"

namespace isotouch::servo {

inline bool HriRenderer::long_step(const FieldView& field, const Vec3& a, const Vec3& b) {
  const Vec3& sp = field.grid().spacing_m;
  const double h = 0.5 * std::min({sp.x, sp.y, sp.z});
  const Vec3 d = b - a;
  return dot(d, d) > h * h;
}

[[gnu::always_inline]] inline Vec3 HriRenderer::contact_force(const FieldView& field, const Vec3& hip, const Vec3& v, double dt,
                                TickOut& out) {
  const bool robust = params_.variant == Variant::kRobust;
  // Optional force shading: the plane through the previous VHIP first gives a
  // temporary HIP, which the true plane then constrains.
  Vec3 goal = hip;
  bool goal_is_hip = true;
  if (params_.force_shading && was_contact_) {
    const Vec3 ns = outward_normal(field, vhip_, plane_.n);
    const double behind = dot(ns, vhip_ - hip);
    if (behind > 0) {
      goal = hip + ns * behind;
      goal_is_hip = false;
    }
  }
  // eq. 2: VHIP = HIP + ((p - HIP) . N) N   (for the goal point)
  const double g = dot(plane_.n, plane_.p - goal);
  const Vec3 free_vhip = (g > 0 || robust) ? goal + plane_.n * g : goal;
  // Paper variant: was the VHIP of the tick before embedded? Only recovery asks, at an update.
  const bool embedded = !robust && params_.recovery_time_s > 0 && out.plane_update && was_contact_ &&
                        excess(sample_value(field, vhip_)) > 0.0;
  const bool friction = params_.friction.any() && was_contact_;
  vhip_ = friction ? constrain(hip, free_vhip, dt) : free_vhip;
  if (!friction) sliding_ = false;

  const double s = inv_wpd_;
  // Recovery time: ramp the magnitude, keep the new direction.
  const bool ramps = params_.recovery_time_s > 0 || recovery_ticks_left_ > 0;
  if (robust && !friction && goal_is_hip) {
    // The robust frictionless tick: HIP - VHIP = -g N (eq. 2), so eq. 3 is N times the
    // scalar K s g - B (v . N), clipped at zero; |F| and the penetration without a square
    // root (|N| = 1 to rounding, so they differ from the vector form's norms in the last bits).
    const double m = params_.stiffness_n_per_m * (g * s) - params_.damping_n_s_per_m * dot(v, plane_.n);
    const bool push = !(m <= 0.0);  // a wall pushes, never pulls (NaN kept: finish_robust's fault)
    const Vec3 force = push ? plane_.n * m : Vec3{};
    out.contact = true;
    out.penetration_m = std::abs(g);
    if (!ramps) {
      out.force_mag = push ? m : 0.0;
      return force;
    }
    // With no ramp running the ramp returns `force` itself: its magnitude is m.
    bool ramped = false;
    const Vec3 sent = robust_ramp(force, hip, v, out, ramped);
    if (!ramped) out.force_mag = push ? m : 0.0;
    return sent;
  }
  const Vec3 d = (hip - vhip_) * s;  // device [m]
  const Vec3 v_d = plane_.n * dot(v, plane_.n);
  // eq. 3 with the physical sign: push the HIP back toward the VHIP.
  Vec3 force = d * -params_.stiffness_n_per_m - v_d * params_.damping_n_s_per_m;
  if (dot(force, plane_.n) < 0.0) force = {};  // a wall pushes, never pulls

  if (ramps && robust) {
    bool ramped = false;
    force = robust_ramp(force, hip, v, out, ramped);
  } else if (ramps) {
    const double mag = norm(force);
    if (embedded && mag > prev_force_mag_ && params_.recovery_time_s > 0) {
      recovery_ticks_ = std::max(1, int(std::lround(params_.recovery_time_s / dt)));
      recovery_ticks_left_ = recovery_ticks_;
      recovery_from_n_ = prev_force_mag_;
    }
    if (recovery_ticks_left_ > 0) {
      const double frac = double(recovery_ticks_ - recovery_ticks_left_ + 1) / recovery_ticks_;
      const double cap = recovery_from_n_ + (mag - recovery_from_n_) * frac;
      if (mag > cap && mag > 0) force = force * (cap / mag);
      --recovery_ticks_left_;
    }
  }
  out.contact = true;
  out.penetration_m = norm(hip - vhip_);
  return force;
}

// A non-finite |F| is a fault (zero force); above the limit the force is saturated, its
// direction kept. mag: |force| on entry, the |F| sent on return.
[[gnu::always_inline]] inline void HriRenderer::limit_force(Vec3& force, double& mag, TickOut& out) const {
  if (!std::isfinite(mag)) {
    force = {};
    mag = 0;
    out.fault = true;
  } else if (mag > params_.force_limit_n) {
    out.saturated = saturate(force, params_.force_limit_n);
    mag = norm(force);
  }
}

// Velocity: backward difference over the measured time `elapsed` [s] from the HIP of the
// last sane tick, first-order low-pass (v_filt_, device [m/s]).
[[gnu::always_inline]] inline void HriRenderer::filter_velocity(const Vec3& hip, double elapsed) {
  const double s = inv_wpd_;
  const bool nominal = elapsed == dt_nominal_s_;  // the common case: no division
  const Vec3 raw = (hip - prev_hip_) * (nominal ? s * params_.rate_hz : s / elapsed);
  const double fc = params_.velocity_cutoff_hz;
  if (fc > 0) {
    const double a = nominal ? alpha_nominal_ : elapsed / (elapsed + 1.0 / (2.0 * M_PI * fc));
    v_filt_ = v_filt_ + (raw - v_filt_) * a;
  } else {
    v_filt_ = raw;
  }
}

}  // namespace isotouch::servo
