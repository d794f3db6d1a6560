// hri_paper.cpp - Figure 2 of the paper exactly as printed (Variant::kPaper), for Table 1
// and the reports: the counter checked before it is incremented (`IF c >= n THEN c = 0 ...
// ELSE c = c + 1`, so the plane is recomputed every n+1 ticks), the plane dropped at an
// update that finds the HIP outside, p = LinearInterpolation(VHIP, HIP, tau) (eq. 1) and
// N = SurfaceNormal(p) by central differences (plane_at, hri_plane.cpp), the VHIP and F by
// eqs. 2 and 3 (contact_force, hri_inline.h). The guards added to the figure are the ones
// both variants share (hri.h, "Common to both": t clamped, no pull, |F| saturated, a
// non-finite HIP or |F| sent as zero force, an absurd HIP a fault and a restart).
// Also §3.1, surface effects by constraining the VHIP (static, dynamic and viscous
// friction, after Salisbury et al.), which both variants use.
// The robust variant's departures from this figure: hri_robust.cpp, hri_plane.cpp.

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>

#include "isotouch/servo/hri_inline.h"
#include "isotouch/servo/sampling.h"

namespace isotouch::servo {

Vec3 HriRenderer::constrain(const Vec3& hip, const Vec3& free_vhip, double dt) {
  // Surface effects by constraining the VHIP (§3.1). Distances in world [m]. The Coulomb
  // cone is tested first on the held point; only then may viscous friction move it.
  const SurfaceFriction& fr = params_.friction;
  const Vec3& n = plane_.n;
  const Vec3 held = vhip_ - n * dot(n, vhip_ - plane_.p);  // last contact point, on this plane
  Vec3 target = free_vhip;
  if (fr.mu_s > 0 || fr.mu_d > 0) {
    const double depth = std::max(0.0, dot(n, plane_.p - hip));  // normal penetration [m]
    const Vec3 t = held - free_vhip;
    const double tl = norm(t);
    if (!sliding_ && tl <= fr.mu_s * depth) return held;  // static: inside the cone
    const double limit = fr.mu_d * depth;                 // dynamic: |F_t| = mu_d |F_n|
    if (tl <= limit) {
      sliding_ = false;
      return held;
    }
    sliding_ = true;
    target = free_vhip + t * (limit / tl);
  }
  if (fr.viscous_n_s_per_m > 0) {
    // Backward Euler of b_v dx/dt = K (target - x): steady sliding adds |F_t| = b_v v.
    const double kt = params_.stiffness_n_per_m * dt / params_.world_per_device;
    return held + (target - held) * (kt / (fr.viscous_n_s_per_m + kt));
  }
  return target;
}

[[gnu::noinline]] HriTick HriRenderer::tick_paper(const FieldView& field, const Vec3& hip) {
  TickOut out;
  const bool absurd = finite(hip) && norm(hip - field.grid().centre_m()) > params_.max_reach_m;
  if (!finite(hip) || absurd) {  // a device fault: send nothing
    out.fault = true;
    resync_ = resync_ || absurd;
    prev_force_mag_ = 0;
    return result(out, plane_);
  }
  if (!started_ || resync_) restart_at(hip);
  const double f_hip = sample_value(field, hip);
  const bool hip_inside = excess(f_hip) > 0.0;
  // p = LinearInterpolation(VHIP, HIP, tau), N = SurfaceNormal(p).
  auto linear_plane = [&](double f_vhip) {
    const double e0 = excess(f_vhip), e1 = excess(f_hip);
    double t = -e0 / (e1 - e0);
    if (!std::isfinite(t)) t = 0.0;
    t = std::clamp(t, 0.0, 1.0);
    return plane_at(field, vhip_ + (hip - vhip_) * t, hip);
  };
  if (plane_.valid) {
    if (c_ >= params_.plane_update_period) {  // as printed: checked before the increment
      c_ = 0;
      if (!hip_inside) {
        plane_.valid = false;
      } else {
        plane_ = linear_plane(sample_value(field, vhip_));
        out.plane_update = true;
      }
    } else {
      ++c_;
    }
  } else if (hip_inside) {
    const double f_vhip = sample_value(field, vhip_);
    if (!(excess(f_vhip) > 0.0)) {
      plane_ = linear_plane(f_vhip);
      out.plane_update = true;
    }
  }
  Vec3 force;
  if (plane_.valid && dot(plane_.n, hip - plane_.p) < 0.0) {
    const Vec3 v = (hip - prev_hip_) * (params_.rate_hz / params_.world_per_device);  // device [m/s]
    force = contact_force(field, hip, v, 1.0 / params_.rate_hz, out);
  } else {
    vhip_ = hip;
    sliding_ = false;
    recovery_ticks_left_ = 0;
    prev_target_f_ = {};
  }
  if (!std::isfinite(norm(force))) {
    force = {};
    out.fault = true;
  } else {
    out.saturated = saturate(force, params_.force_limit_n);
  }
  prev_hip_ = hip;
  prev_force_mag_ = norm(force);
  was_contact_ = out.contact;
  out.force_n = force;
  return result(out, plane_);
}

}  // namespace isotouch::servo
