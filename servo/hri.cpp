#include "hri.h"

#include <algorithm>
#include <cmath>

#include "sampling.h"

namespace isotouch::servo {

void HriRenderer::reset() {
  plane_ = {};
  c_ = 0;
  started_ = false;
  resync_ = false;
  sliding_ = false;
  was_contact_ = false;
  recovery_ticks_left_ = 0;
  prev_force_mag_ = 0;
}

Vec3 HriRenderer::outward_normal(const SampleField& field, const Vec3& x, const Vec3& fallback) const {
  Vec3 g;
  switch (params_.normal) {
    case NormalSource::kSamples:
      g = sample_trilinear(field, x).gradient;
      break;
    case NormalSource::kCentral: {
      const Vec3 h = field.grid.spacing_m * 0.5;
      g = {(sample_value(field, x + Vec3{h.x, 0, 0}) - sample_value(field, x - Vec3{h.x, 0, 0})) / (2 * h.x),
           (sample_value(field, x + Vec3{0, h.y, 0}) - sample_value(field, x - Vec3{0, h.y, 0})) / (2 * h.y),
           (sample_value(field, x + Vec3{0, 0, h.z}) - sample_value(field, x - Vec3{0, 0, h.z})) / (2 * h.z)};
      break;
    }
    case NormalSource::kTrilinearExact:
      g = trilinear_field_gradient(field, x);
      break;
  }
  return normalized_or(params_.inside == InsideIs::kAbove ? -g : g, fallback);
}

VirtualPlane HriRenderer::plane_at(const SampleField& field, const Vec3& p, const Vec3& hip) const {
  VirtualPlane plane;
  plane.p = p;
  const Vec3 fallback = normalized_or(vhip_ - hip, plane_.valid ? plane_.n : Vec3{0.0, 0.0, 1.0});
  plane.n = outward_normal(field, p, fallback);
  plane.valid = finite(plane.p) && finite(plane.n);
  return plane;
}

bool HriRenderer::long_step(const SampleField& field, const Vec3& a, const Vec3& b) {
  const Vec3& sp = field.grid.spacing_m;
  return norm(b - a) > 0.5 * std::min({sp.x, sp.y, sp.z});
}

bool HriRenderer::first_crossing(const SampleField& field, const Vec3& a, const Vec3& b,
                                 Vec3& p) const {
  const Vec3& sp = field.grid.spacing_m;
  const double len = norm(b - a);
  const double h = 0.5 * std::min({sp.x, sp.y, sp.z});
  if (!(len > h) || !std::isfinite(len)) return false;
  const int steps = int(std::min(4096.0, std::ceil(len / h)));
  double lo = 0.0;
  for (int i = 1; i <= steps; ++i) {
    const double t = double(i) / steps;
    if (excess(sample_value(field, a + (b - a) * t)) > 0.0) {
      double hi = t;
      for (int k = 0; k < 30; ++k) {
        const double mid = 0.5 * (lo + hi);
        (excess(sample_value(field, a + (b - a) * mid)) > 0.0 ? hi : lo) = mid;
      }
      p = a + (b - a) * lo;  // last point known outside: on the surface to 1e-9 of len
      return true;
    }
    lo = t;
  }
  return false;
}

VirtualPlane HriRenderer::compute_plane(const SampleField& field, double f_vhip, double f_hip,
                                        const Vec3& hip) const {
  // p = LinearInterpolation(VHIP, HIP, tau)  (Figure 2, eq. 1), optionally refined.
  const double e0 = excess(f_vhip), e1 = excess(f_hip);
  const Vec3& sp = field.grid.spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const double gn0 = e0 > 0.0 ? norm(sample_trilinear(field, vhip_).gradient) : 0.0;
  const double d_est = gn0 > 0 ? e0 / gn0 : voxel;
  if (e0 > 0.0 && d_est > 1e-4 * voxel) {
    // The VHIP is embedded (Figure 5b): the two ends do not bracket tau and the linear
    // rule would extrapolate. Look for the surface from the VHIP along its outward
    // normal, no farther than twice the first-order depth e0 / |grad| plus a quarter
    // voxel (so it cannot jump through a thin feature); keep p = VHIP if none. An
    // embedding below 1e-4 voxel is rounding, not Figure 5b.
    const Vec3 n0 = outward_normal(field, vhip_, plane_.valid ? plane_.n : Vec3{0, 0, 1});
    const double reach = std::min(8.0 * voxel, 2.0 * d_est + 0.25 * voxel);
    if (excess(sample_value(field, vhip_ + n0 * reach)) <= 0.0) {
      double lo = 0.0, hi = reach;
      for (int k = 0; k < 16; ++k) {
        const double mid = 0.5 * (lo + hi);
        (excess(sample_value(field, vhip_ + n0 * mid)) > 0.0 ? lo : hi) = mid;
      }
      return plane_at(field, vhip_ + n0 * hi, hip);
    }
    return plane_at(field, vhip_, hip);
  }
  double t = -e0 / (e1 - e0);
  if (!std::isfinite(t)) t = 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const Vec3 seg = hip - vhip_;
  if (params_.intersection != Intersection::kLinear && e0 <= 0.0 && e1 > 0.0) {
    double a = 0, fa = e0, b = 1, fb = e1;
    if (params_.intersection == Intersection::kBisection) {
      for (int k = 0; k < params_.intersection_steps; ++k) {
        const double mid = 0.5 * (a + b);
        const double fm = excess(sample_value(field, vhip_ + seg * mid));
        if (fm > 0.0) { b = mid; fb = fm; } else { a = mid; fa = fm; }
      }
      t = a - fa * (b - a) / (fb - fa);
    } else {  // Illinois regula falsi: keeps the bracket, converges superlinearly
      int side = 0;
      for (int k = 0; k < params_.intersection_steps; ++k) {
        t = a - fa * (b - a) / (fb - fa);
        const double ft = excess(sample_value(field, vhip_ + seg * t));
        if (ft > 0.0) {
          b = t; fb = ft;
          if (side == 1) fa *= 0.5;
          side = 1;
        } else {
          a = t; fa = ft;
          if (side == -1) fb *= 0.5;
          side = -1;
        }
      }
      t = a - fa * (b - a) / (fb - fa);
    }
    if (!std::isfinite(t)) t = 0.5 * (a + b);
    t = std::clamp(t, 0.0, 1.0);
  }
  // N = SurfaceNormal(p): outward unit normal.
  return plane_at(field, vhip_ + seg * t, hip);
}

Vec3 HriRenderer::constrain(const Vec3& hip, const Vec3& free_vhip) {
  // Surface effects by constraining the VHIP (§3.1). Distances in world [m].
  const SurfaceFriction& fr = params_.friction;
  const Vec3& n = plane_.n;
  Vec3 held = vhip_ - n * dot(n, vhip_ - plane_.p);  // last contact point, on this plane
  if (fr.viscous_n_s_per_m > 0) {
    // Backward Euler of b_v dx/dt = K (free - x): steady sliding gives |F_t| = b_v v exactly.
    const double kt = params_.stiffness_n_per_m / params_.rate_hz;
    held = held + (free_vhip - held) * (kt / (fr.viscous_n_s_per_m + kt));
  }
  if (!(fr.mu_s > 0 || fr.mu_d > 0)) return held;
  const double depth = std::max(0.0, dot(n, plane_.p - hip));  // normal penetration [m]
  const Vec3 t = held - free_vhip;
  const double tl = norm(t);
  if (!sliding_ && tl <= fr.mu_s * depth) return held;        // static: inside the cone
  const double limit = fr.mu_d * depth;                       // dynamic: |F_t| = mu_d |F_n|
  if (tl <= limit) {
    sliding_ = false;
    return held;
  }
  sliding_ = true;
  return free_vhip + t * (limit / tl);
}

HriTick HriRenderer::tick(const SampleField& field, const Vec3& hip, double dt_s) {
  (void)dt_s;
  HriTick out;
  const bool absurd = finite(hip) && norm(hip - field.grid.centre_m()) > params_.max_reach_m;
  if (!finite(hip) || absurd) {  // a device fault: send nothing
    out.fault = true;
    resync_ = resync_ || absurd;
    out.vhip_m = vhip_;
    out.plane = plane_;
    prev_force_mag_ = 0;
    return out;
  }
  if (!started_ || resync_) {
    vhip_ = hip;
    prev_hip_ = hip;
    plane_ = {};
    c_ = 0;
    started_ = true;
    resync_ = false;
    sliding_ = false;
    was_contact_ = false;
    recovery_ticks_left_ = 0;
    prev_force_mag_ = 0;
  }
  const double f_hip = sample_value(field, hip);
  const bool hip_inside = excess(f_hip) > 0.0;

  if (plane_.valid) {
    if (++c_ >= params_.plane_update_period) {
      c_ = 0;
      Vec3 p;
      if (!hip_inside) {
        // VirtualPlane = (0, 0), unless the HIP went through a thin wall since the VHIP.
        if (!(excess(sample_value(field, vhip_)) > 0.0) && first_crossing(field, vhip_, hip, p)) {
          plane_ = plane_at(field, p, hip);
          out.plane_update = true;
        } else {
          plane_.valid = false;
        }
      } else {
        plane_ = compute_plane(field, sample_value(field, vhip_), f_hip, hip);
        out.plane_update = true;
      }
    }
  } else if (hip_inside) {
    const double f_vhip = sample_value(field, vhip_);
    if (!(excess(f_vhip) > 0.0)) {  // the ray VHIP -> HIP enters the object
      plane_ = compute_plane(field, f_vhip, f_hip, hip);
      c_ = 0;
      out.plane_update = true;
    }
  } else {
    // Both ends outside: a long step may have jumped over a thin wall. Short steps (the
    // common case) cost nothing here: the length is checked before any sample.
    Vec3 p;
    if (long_step(field, vhip_, hip) && !(excess(sample_value(field, vhip_)) > 0.0) &&
        first_crossing(field, vhip_, hip, p)) {
      plane_ = plane_at(field, p, hip);
      c_ = 0;
      out.plane_update = true;
    }
  }

  Vec3 force;
  if (plane_.valid && dot(plane_.n, hip - plane_.p) < 0.0) {
    // Optional force shading: the plane through the previous VHIP first gives a
    // temporary HIP, which the true plane then constrains.
    Vec3 goal = hip;
    if (params_.force_shading && was_contact_) {
      const Vec3 ns = outward_normal(field, vhip_, plane_.n);
      const double behind = dot(ns, vhip_ - hip);
      if (behind > 0) goal = hip + ns * behind;
    }
    // eq. 2: VHIP = HIP + ((p - HIP) . N) N   (for the goal point)
    const double g = dot(plane_.n, plane_.p - goal);
    const Vec3 free_vhip = g > 0 ? goal + plane_.n * g : goal;
    // Was the VHIP of the tick before embedded? Only recovery time asks, and only at an update.
    const bool embedded = params_.recovery_time_s > 0 && out.plane_update && was_contact_ &&
                          excess(sample_value(field, vhip_)) > 0.0;
    vhip_ = (params_.friction.any() && was_contact_) ? constrain(hip, free_vhip) : free_vhip;
    if (!(params_.friction.any() && was_contact_)) sliding_ = false;

    const double s = 1.0 / params_.world_per_device;
    const Vec3 d = (hip - vhip_) * s;                          // device [m]
    const Vec3 v = (hip - prev_hip_) * (params_.rate_hz * s);  // device [m/s]
    const Vec3 v_d = plane_.n * dot(v, plane_.n);
    // eq. 3 with the physical sign: push the HIP back toward the VHIP.
    force = d * -params_.stiffness_n_per_m - v_d * params_.damping_n_s_per_m;
    if (dot(force, plane_.n) < 0.0) force = {};  // a wall pushes, never pulls

    // Recovery time: a new plane that leaves the old VHIP embedded would make the force
    // jump; keep the direction and ramp the magnitude instead.
    const double mag = norm(force);
    if (embedded && mag > prev_force_mag_) {
      recovery_ticks_ = std::max(1, int(std::lround(params_.recovery_time_s * params_.rate_hz)));
      recovery_ticks_left_ = recovery_ticks_;
      recovery_from_n_ = prev_force_mag_;
    }
    if (recovery_ticks_left_ > 0) {
      const double frac = double(recovery_ticks_ - recovery_ticks_left_ + 1) / recovery_ticks_;
      const double cap = recovery_from_n_ + (mag - recovery_from_n_) * frac;
      if (mag > cap && mag > 0) force = force * (cap / mag);
      --recovery_ticks_left_;
    }
    out.contact = true;
    out.penetration_m = norm(hip - vhip_);
  } else {
    vhip_ = hip;
    sliding_ = false;
    recovery_ticks_left_ = 0;
  }

  const double mag = norm(force);
  if (!std::isfinite(mag)) {
    force = {};
    out.fault = true;
  } else {
    out.saturated = saturate(force, params_.force_limit_n);
  }
  prev_hip_ = hip;
  prev_force_mag_ = norm(force);
  was_contact_ = out.contact;
  out.force_n = force;
  out.vhip_m = vhip_;
  out.plane = plane_;
  return out;
}

}  // namespace isotouch::servo
