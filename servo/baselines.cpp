#include "isotouch/servo/baselines.h"

#include <algorithm>
#include <cmath>

#include "isotouch/servo/sampling.h"

namespace isotouch::servo {
namespace {
bool fault_position(const FieldView& field, const Vec3& hip, double reach) {
  return !finite(hip) || norm(hip - field.grid().centre_m()) > reach;
}
/// 1 / the period [1/s]: the measured dt_s when it is positive and finite, else the
/// nominal 1 / rate.
double inv_period(double dt_s, double rate_hz) {
  return (dt_s > 0 && std::isfinite(dt_s)) ? 1.0 / dt_s : rate_hz;
}
void finish(HriTick& out, Vec3 force, double limit) {
  if (!finite(force)) {
    force = {};
    out.fault = true;
  }
  out.saturated = saturate(force, limit);
  out.force_n = force;
}
}  // namespace

HriTick AvilaRenderer::tick(const FieldView& field, const Vec3& hip, double dt_s) {
  HriTick out;
  if (fault_position(field, hip, p_.max_reach_m)) {
    out.fault = true;
    started_ = false;
    return out;
  }
  if (!started_) {
    prev_hip_ = hip;
    started_ = true;
  }
  const FieldValue fv = sample_trilinear(field, hip);
  const Isosurface iso{p_.tau, p_.inside};
  const double e = iso.excess(fv.value);
  const Vec3 g_out = iso.outward(fv.gradient);
  const double gn = norm(g_out);
  Vec3 force;
  out.vhip_m = hip;
  if (e > 0 && gn > 0 && std::isfinite(gn)) {
    const Vec3 n = g_out / gn;
    const double d_est = e / gn;  // world [m]
    const double s = 1.0 / p_.world_per_device;
    const Vec3 v = (hip - prev_hip_) * (inv_period(dt_s, p_.rate_hz) * s);
    force = n * (p_.stiffness_n_per_m * d_est * s) - v * p_.damping_n_s_per_m;
    out.contact = true;
    out.vhip_m = hip + n * d_est;
    out.penetration_m = d_est;
  }
  prev_hip_ = hip;
  finish(out, force, p_.force_limit_n);
  return out;
}

Vec3 BlezekRenderer::gradient(const FieldView& field, const Vec3& x) const {
  const Vec3 h = field.grid().spacing_m * p_.central_h_voxels;
  const Vec3 g{(excess(sample_value(field, x + Vec3{h.x, 0, 0})) - excess(sample_value(field, x - Vec3{h.x, 0, 0}))) / (2 * h.x),
               (excess(sample_value(field, x + Vec3{0, h.y, 0})) - excess(sample_value(field, x - Vec3{0, h.y, 0}))) / (2 * h.y),
               (excess(sample_value(field, x + Vec3{0, 0, h.z})) - excess(sample_value(field, x - Vec3{0, 0, h.z}))) / (2 * h.z)};
  return finite(g) ? g : Vec3{};
}

HriTick BlezekRenderer::tick(const FieldView& field, const Vec3& hip, double dt_s) {
  HriTick out;
  if (fault_position(field, hip, p_.max_reach_m)) {
    out.fault = true;
    started_ = false;
    contact_ = false;
    return out;
  }
  if (!started_) {
    prev_hip_ = hip;
    vhip_ = hip;
    started_ = true;
  }
  const bool inside = excess(sample_value(field, hip)) > 0;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  if (!inside) {
    contact_ = false;
  } else if (!contact_ && !(excess(sample_value(field, prev_hip_)) > 0)) {
    // Entering: the contact point starts at the crossing.
    double lo = 0, hi = 1;
    for (int k = 0; k < 8; ++k) {
      const double mid = 0.5 * (lo + hi);
      (excess(sample_value(field, prev_hip_ + (hip - prev_hip_) * mid)) > 0 ? hi : lo) = mid;
    }
    vhip_ = prev_hip_ + (hip - prev_hip_) * lo;
    contact_ = true;
  }
  Vec3 force;
  if (contact_) {
    // Gradient of the excess points inward; the outward normal is its negative.
    bool failed = false;
    Vec3 n;
    for (int it = 0; it < p_.inch_iterations; ++it) {
      const Vec3 g = gradient(field, vhip_);
      const double gn = norm(g);
      if (!(gn > 0)) {
        failed = true;
        break;
      }
      n = g / -gn;
      const Vec3 r = hip - vhip_;
      Vec3 t = r - n * dot(r, n);
      const double tl = norm(t);
      if (tl < 1e-3 * voxel) break;
      const double max_step = p_.inch_step_voxels * voxel;
      if (tl > max_step) t = t * (max_step / tl);
      Vec3 x = vhip_ + t;
      // Back onto the isosurface: one Newton step along the gradient.
      const Vec3 gx = gradient(field, x);
      const double g2 = dot(gx, gx);
      if (!(g2 > 0)) {
        failed = true;
        break;
      }
      x = x - gx * (excess(sample_value(field, x)) / g2);
      if (!finite(x)) {
        failed = true;
        break;
      }
      vhip_ = x;
    }
    if (!failed) {
      const Vec3 g = gradient(field, vhip_);
      const double gn = norm(g);
      if (gn > 0) n = g / -gn; else failed = true;
    }
    if (!failed) {
      const double s = 1.0 / p_.world_per_device;
      const Vec3 d = (hip - vhip_) * s;
      const Vec3 v = (hip - prev_hip_) * (inv_period(dt_s, p_.rate_hz) * s);
      force = d * -p_.stiffness_n_per_m - n * (dot(v, n) * p_.damping_n_s_per_m);
      if (dot(force, n) < 0) force = {};
    }
    out.contact = true;
    out.vhip_m = vhip_;
    out.penetration_m = norm(hip - vhip_);
    out.plane.n = n;
    out.plane.p = vhip_;
  } else {
    vhip_ = hip;
    out.vhip_m = hip;
  }
  prev_hip_ = hip;
  finish(out, force, p_.force_limit_n);
  return out;
}

}  // namespace isotouch::servo
