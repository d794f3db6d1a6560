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
}

VirtualPlane HriRenderer::plane_at(const SampleField& field, const Vec3& p, const Vec3& hip) const {
  VirtualPlane plane;
  plane.p = p;
  const FieldValue fv = sample_trilinear(field, p);
  const Vec3 g = params_.inside == InsideIs::kAbove ? -fv.gradient : fv.gradient;
  const Vec3 fallback = normalized_or(
      vhip_ - hip, plane_.valid ? plane_.n : Vec3{0.0, 0.0, 1.0});
  plane.n = normalized_or(g, fallback);
  plane.valid = finite(plane.p) && finite(plane.n);
  return plane;
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

VirtualPlane HriRenderer::compute_plane(const SampleField& field, double f_vhip,
                                        double f_hip, const Vec3& hip) const {
  // p = LinearInterpolation(VHIP, HIP, tau)  (Figure 2, eq. 1)
  const double denom = f_hip - f_vhip;
  double t = (params_.tau - f_vhip) / denom;
  if (!std::isfinite(t)) t = 0.0;
  t = std::clamp(t, 0.0, 1.0);
  // N = SurfaceNormal(p): outward unit normal from the published gradient.
  return plane_at(field, vhip_ + (hip - vhip_) * t, hip);
}

HriTick HriRenderer::tick(const SampleField& field, const Vec3& hip) {
  HriTick out;
  const bool absurd = finite(hip) && norm(hip - field.grid.centre_m()) > params_.max_reach_m;
  if (!finite(hip) || absurd) {  // a device fault: send nothing
    out.fault = true;
    resync_ = resync_ || absurd;
    out.vhip_m = vhip_;
    out.plane = plane_;
    return out;
  }
  if (!started_ || resync_) {
    vhip_ = hip;
    prev_hip_ = hip;
    plane_ = {};
    c_ = 0;
    started_ = true;
    resync_ = false;
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
    // Both ends outside: a long step may have jumped over a thin wall.
    Vec3 p;
    if (!(excess(sample_value(field, vhip_)) > 0.0) && first_crossing(field, vhip_, hip, p)) {
      plane_ = plane_at(field, p, hip);
      c_ = 0;
      out.plane_update = true;
    }
  }

  Vec3 force;
  if (plane_.valid && dot(plane_.n, hip - plane_.p) < 0.0) {
    // eq. 2: VHIP = HIP + ((p - HIP) . N) N
    vhip_ = hip + plane_.n * dot(plane_.p - hip, plane_.n);
    const double s = 1.0 / params_.world_per_device;
    const Vec3 d = (hip - vhip_) * s;                       // device [m]
    const Vec3 v = (hip - prev_hip_) * (params_.rate_hz * s);  // device [m/s]
    const Vec3 v_d = plane_.n * dot(v, plane_.n);
    // eq. 3 with the physical sign: push the HIP back toward the VHIP.
    force = d * -params_.stiffness_n_per_m - v_d * params_.damping_n_s_per_m;
    if (dot(force, plane_.n) < 0.0) force = {};  // a wall pushes, never pulls
    out.contact = true;
    out.penetration_m = norm(hip - vhip_);
  } else {
    vhip_ = hip;
  }

  const double mag = norm(force);
  if (!std::isfinite(mag)) {
    force = {};
    out.fault = true;
  } else if (mag > params_.force_limit_n) {
    force = force * (params_.force_limit_n / mag);
    out.saturated = true;
  }
  prev_hip_ = hip;
  out.force_n = force;
  out.vhip_m = vhip_;
  out.plane = plane_;
  return out;
}

}  // namespace isotouch::servo
