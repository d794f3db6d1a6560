#include "hri.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "sampling.h"

namespace isotouch::servo {
namespace {
/// `steps` bisection steps on [lo, hi]: each halves the bracket at mid = (lo + hi) / 2,
/// keeping the half [mid, hi] where lo_side(mid) holds, else [lo, mid]. Two steps per
/// round: the midpoint and both possible next midpoints are read at once (independent
/// reads, no branch on the first outcome), the same midpoints, hence the same bracket
/// bit for bit as one step at a time, in half the dependent chain.
template <class LoSide>
[[gnu::always_inline]] inline void bisect(double& lo, double& hi, int steps, LoSide lo_side) {
  for (; steps >= 2; steps -= 2) {
    const double mid = 0.5 * (lo + hi);
    const double ml = 0.5 * (lo + mid), mh = 0.5 * (mid + hi);
    const bool pm = lo_side(mid), pl = lo_side(ml), ph = lo_side(mh);
    const double lo1 = pm ? mid : lo, hi1 = pm ? hi : mid;
    const double m2 = pm ? mh : ml;
    const bool p2 = pm ? ph : pl;
    lo = p2 ? m2 : lo1;
    hi = p2 ? hi1 : m2;
  }
  if (steps > 0) {
    const double mid = 0.5 * (lo + hi);
    (lo_side(mid) ? lo : hi) = mid;
  }
}

/// The direction from unit `a` to unit `b` with a fraction `s` of the turn still to go
/// (1: a, 0: b). Within 90 deg a normalized blend of the two (its rate varies at most 2x over
/// the ramp); beyond, a rotation in the plane of the two at a steady rate: there the blend
/// swings through the middle in a few ticks (150 deg over 20 ticks: 20 deg in one) and, near
/// 180 deg, flips. Opposite directions turn about an axis perpendicular to `a`.
Vec3 turn_toward(const Vec3& a, const Vec3& b, double s) {
  const double c = dot(a, b);
  if (c >= 0.0) return normalized_or(b * (1.0 - s) + a * s, b);
  Vec3 perp = b - a * c;  // toward b, perpendicular to a
  double pl = norm(perp);
  const double whole = std::atan2(pl, c);  // the turn's angle, in (90, 180] deg
  if (!(pl > 1e-9)) {  // opposite: any perpendicular, the same one every time
    const Vec3 e = std::abs(a.x) < 0.5 ? Vec3{1.0, 0.0, 0.0} : Vec3{0.0, 1.0, 0.0};
    perp = cross(cross(a, e), a);
    pl = norm(perp);
  }
  const double angle = whole * (1.0 - s);
  return normalized_or(a * std::cos(angle) + perp * (std::sin(angle) / pl), b);
}
}  // namespace


HriRenderer::HriRenderer(const HriParams& params) : params_(params) {
  if (params_.variant == Variant::kPaper) {
    // Figure 2: p = LinearInterpolation(VHIP, HIP, tau), N = SurfaceNormal(p) "approximated
    // by using central difference" (§2): the scene's choices do not apply to the paper.
    params_.intersection = Intersection::kLinear;
    params_.normal = NormalSource::kCentral;
  }
  dt_nominal_s_ = 1.0 / params_.rate_hz;
  inv_wpd_ = 1.0 / params_.world_per_device;
  const double fc = params_.velocity_cutoff_hz;
  alpha_nominal_ = fc > 0 ? dt_nominal_s_ / (dt_nominal_s_ + 1.0 / (2.0 * M_PI * fc)) : 1.0;
  quick_ok_ = params_.variant == Variant::kRobust && params_.short_way && !(params_.tool_radius_m > 0.0) &&
              !params_.force_shading && !params_.friction.any() &&
              std::isfinite(params_.max_reach_m * params_.max_reach_m);
}

void HriRenderer::reset() {
  clear_contact();
  started_ = false;
  plain_ = false;
  after_fault_ = false;
  v_filt_ = {};
  lost_s_ = 0;
  version_known_ = false;
  edit_tick_ = false;
}

void HriRenderer::clear_contact() {
  plane_ = {};
  c_ = 0;
  resync_ = false;
  sliding_ = false;
  was_contact_ = false;
  recovery_ticks_left_ = 0;
  ramp_left_s_ = 0;
  prev_force_mag_ = 0;
  vel_valid_ = false;
  edit_slewing_ = false;
  prev_force_ = {};
  tool_plane_count_ = 0;
  scan_valid_ = false;
  release_left_s_ = 0;
  prev_target_f_ = {};
  ramp_from_dir_ = {};
}

Vec3 HriRenderer::outward_normal(const FieldView& field, const Vec3& x, const Vec3& fallback) const {
  double unused;
  return outward_normal(field, x, fallback, unused);
}

Vec3 HriRenderer::outward_normal(const FieldView& field, const Vec3& x, const Vec3& fallback,
                                 double& grad_norm) const {
  Vec3 g;
  switch (params_.normal) {
    case NormalSource::kSamples: {
      g = sample_trilinear(field, x).gradient;
      if (params_.variant == Variant::kRobust) {
        // Across a structure one or two voxels thick the blended gradient samples of its
        // two faces cancel, and what is left (a taper's slope, noise) can point along the
        // surface: a tapering plate on 3 mm voxels tilted the plane by up to 90 deg and
        // eq. 2 slid the VHIP into the plate. Where the blend turns more than 30 deg from
        // the gradient of the trilinear values (the normal of the isosurface rendered),
        // that gradient is the normal.
        const Vec3 gt = trilinear_field_gradient(field, x);
        const double gs = norm(g), gtn = norm(gt);
        if (gtn > 0 && std::isfinite(gtn) && !(dot(g, gt) > 0.866 * gs * gtn)) g = gt * (gs > 0 && std::isfinite(gs) ? gs / gtn : 1.0);
      }
      break;
    }
    case NormalSource::kCentral:
      g = field.central_difference_half_voxel(x);  // (central_difference with h = spacing / 2)
      break;
    case NormalSource::kTrilinearExact:
      g = trilinear_field_gradient(field, x);
      break;
  }
  // normalized_or(outward(g), fallback) with |outward(g)| = |g| (a negation, exact) taken
  // from grad_norm: one square root (on the update's dependent chain) less.
  grad_norm = norm(g);
  const Vec3 out = Isosurface{params_.tau, params_.inside}.outward(g);
  // One division, three products (a unit vector to an ulp, as out / grad_norm's three divisions).
  return (grad_norm > 0.0 && std::isfinite(grad_norm)) ? out * (1.0 / grad_norm) : fallback;
}

VirtualPlane HriRenderer::plane_at(const FieldView& field, const Vec3& p, const Vec3& hip) const {
  VirtualPlane plane;
  plane.p = p;
  // The fallback (the unit vector HIP -> VHIP, else the held normal) only where the
  // gradient gives no normal: outward_normal returns a finite unit vector or the fallback
  // it was given, so a NaN one marks that case (the same result, no square root otherwise).
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  plane.n = outward_normal(field, p, Vec3{kNaN, kNaN, kNaN}, last_grad_norm_);
  if (!finite(plane.n)) plane.n = normalized_or(vhip_ - hip, plane_.valid ? plane_.n : Vec3{0.0, 0.0, 1.0});
  plane.valid = finite(plane.p) && finite(plane.n);
  return plane;
}

bool HriRenderer::long_step(const FieldView& field, const Vec3& a, const Vec3& b) {
  const Vec3& sp = field.grid().spacing_m;
  const double h = 0.5 * std::min({sp.x, sp.y, sp.z});
  const Vec3 d = b - a;
  return dot(d, d) > h * h;
}

bool HriRenderer::first_crossing(const FieldView& field, const Vec3& a, const Vec3& b,
                                 Vec3& p, double step_voxels) const {
  const Vec3& sp = field.grid().spacing_m;
  const double len = norm(b - a);
  const double h = step_voxels * std::min({sp.x, sp.y, sp.z});
  if (!std::isfinite(len) || !(len > 0.0)) return false;
  // Half-voxel steps, at least 2 (the end point alone says nothing about a thin wall
  // in between), at most march_budget samples (longer steps beyond that).
  const int budget = std::max(2, params_.march_budget);
  const int steps = int(std::clamp(std::ceil(len / h), 2.0, double(budget)));
  FieldView::Segment seg(field, a, b);  // one cubic per cell for the march's reads
  double lo = 0.0;
  for (int i = 1; i <= steps; ++i) {
    const double t = double(i) / steps;
    if (excess(seg.value(t)) > 0.0) {
      double hi = t;
      bisect(lo, hi, 20, [&](double m) { return !(excess(seg.value(m)) > 0.0); });
      p = a + (b - a) * lo;  // last point known outside: on the surface to 1e-6 of the step
      return true;
    }
    lo = t;
  }
  return false;
}

bool HriRenderer::surface_from(const FieldView& field, const Vec3& x, double e_x, double grad_norm,
                               Vec3& p, const Vec3* along) const {
  // Along the outward normal at x, no farther than twice the first-order depth
  // e_x / |grad| plus a quarter voxel (which bounds how far past the surface it looks; a
  // feature thinner than that reach can still lie inside it, and the search then settles on
  // whichever crossing its bracket holds), at most 8 voxels; the crossing to reach / 2^16.
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const double d_est = grad_norm > 0 ? e_x / grad_norm : voxel;
  const Vec3 n0 = along ? *along : outward_normal(field, x, plane_.valid ? plane_.n : Vec3{0, 0, 1});
  const double reach = std::min(8.0 * voxel, 2.0 * d_est + 0.25 * voxel);
  // Reads at x + n0 t as the segment's parameter t / reach (a cell's cubic loaded once).
  FieldView::Segment seg(field, x, x + n0 * reach);
  const double inv_reach = 1.0 / reach;
  const double e_reach = excess(seg.value(1.0));
  if (!(e_reach <= 0.0)) return false;
  // The crossing in [0, reach] (x inside, the far end outside) by Illinois regula falsi: to
  // the width 16 bisection steps leave (reach / 2^16), or until the outside end is that
  // close to the surface to first order. On the table1 strokes 2.4-3.8 reads per call on
  // average, the far end's included, where bisection took 25 (this search was a third of a
  // robust plane update's instructions on the head CT). p is the outside end of the bracket.
  const double width = reach * 0x1p-16;
  double lo = 0.0, hi = reach, e_lo = e_x, e_hi = e_reach;
  int side = 0;  // which end the last read replaced: -1 the inside one, 1 the outside one
  for (int k = 0; k < 24 && hi - lo > width && !(-e_hi <= width * grad_norm); ++k) {
    double t = lo + (hi - lo) * (e_lo / (e_lo - e_hi));
    if (!(t > lo && t < hi)) t = 0.5 * (lo + hi);
    const double e = excess(seg.value(t * inv_reach));
    if (e > 0.0) {
      lo = t;
      e_lo = e;
      if (side == -1) e_hi *= 0.5;  // Illinois: the end kept twice counts half
      side = -1;
    } else {
      hi = t;
      e_hi = e;
      if (side == 1) e_lo *= 0.5;
      side = 1;
    }
  }
  p = x + n0 * hi;
  return true;
}

bool HriRenderer::march_out(const FieldView& field, const Vec3& x, Vec3& p) const {
  // Half-voxel steps along the outward normal at x, at most march_budget samples, to the
  // first point outside; then 20 bisection steps. p is the outside end of the last bracket.
  const Vec3& sp = field.grid().spacing_m;
  const double h = 0.5 * std::min({sp.x, sp.y, sp.z});
  const Vec3 n0 = outward_normal(field, x, plane_.valid ? plane_.n : Vec3{0, 0, 1});
  const int budget = std::max(2, params_.march_budget);
  FieldView::Segment seg(field, x, x + n0 * h);  // parameter: t / h
  double lo = 0.0;
  for (int i = 1; i <= budget; ++i) {
    const double t = h * i;
    if (!(excess(seg.value(double(i))) > 0.0)) {
      double hi = t;
      for (int k = 0; k < 20; ++k) {
        const double mid = 0.5 * (lo + hi);
        (excess(seg.value(mid / h)) > 0.0 ? lo : hi) = mid;
      }
      p = x + n0 * hi;
      return true;
    }
    lo = t;
  }
  return false;
}

VirtualPlane HriRenderer::compute_plane(const FieldView& field, double f_vhip, double f_hip,
                                        const Vec3& hip) const {
  // p = LinearInterpolation(VHIP, HIP, tau)  (Figure 2, eq. 1), optionally refined.
  const double e0 = excess(f_vhip), e1 = excess(f_hip);
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  // |grad| near the VHIP: the one measured with the held plane's normal (robust, no
  // sample), else read at the VHIP.
  const double gn0 = !(e0 > 0.0) ? 0.0
                     : (params_.variant == Variant::kRobust && plane_.valid && plane_grad_norm_ > 0)
                         ? plane_grad_norm_
                         : norm(sample_trilinear(field, vhip_).gradient);
  const double d_est = gn0 > 0 ? e0 / gn0 : voxel;
  if (e0 > 0.0 && d_est > 1e-4 * voxel && d_est <= 0.05 * voxel && plane_.valid &&
      params_.variant == Variant::kRobust) {
    // Shallow embedding (a chord or a plane held over a curved surface): one step out along
    // the held plane's normal, if that reaches the outside (one sample), of 1.5 times the
    // first-order depth, at most 0.05 voxel. The VHIP is inside and that point outside, so
    // a crossing lies between them: p is outside the surface by at most 0.05 voxel (the
    // worst case a step of the depth alone allowed too; about half the depth where the
    // first-order depth is exact, where that step landed on the surface). A step of the
    // depth alone fell short in 111 of 164 such updates per table1 replay of the head CT
    // (63 of 172 at 1.5 times), each then paying the search below, about as much again as
    // the update. Where |grad| overstates the slope of the trilinear values (a plate one
    // voxel thick on coarse voxels) the step falls short, and the VHIP sank by 0.2 voxel a
    // few hundredths of a mm per tick: then the search below.
    const Vec3 out_p = vhip_ + plane_.n * std::min(1.5 * d_est, 0.05 * voxel);
    if (!(excess(sample_value(field, out_p)) > 0.0)) return plane_at(field, out_p, hip);
  }
  if (e0 > 0.0 && d_est > 1e-4 * voxel) {
    // The VHIP is embedded (Figure 5b): the two ends do not bracket tau and the linear
    // rule would extrapolate. Look for the surface from the VHIP along its outward
    // normal (see surface_from); keep p = VHIP if none. An embedding below 1e-4 voxel is
    // rounding, not Figure 5b.
    // On an edit tick, material added deeper than that reach: march out (march_out).
    Vec3 p;
    // Robust, with a plane held: first along the held normal, the way the contact point
    // came in (on a noisy scan the gradient at an embedded point can point sideways, and
    // the surface found along it lies on another sheet: a plane turned by up to 106 deg in
    // one update on the head CT).
    const bool held = params_.variant == Variant::kRobust && plane_.valid;
    const bool found = (held && surface_from(field, vhip_, e0, gn0, p, &plane_.n)) ||
                       surface_from(field, vhip_, e0, gn0, p) || (edit_tick_ && march_out(field, vhip_, p));
    return plane_at(field, found ? p : vhip_, hip);
  }
  if (edit_tick_ && !(e0 > 0.0) && e1 > 0.0) {
    // Edit tick, VHIP outside, HIP inside: after a carve the VHIP may be far in the air,
    // even in a uniform brick whose tile reads the isovalue itself, where the linear rule
    // would put p at the VHIP. March the segment for its first crossing (first_crossing).
    Vec3 p;
    if (first_crossing(field, vhip_, hip, p)) return plane_at(field, p, hip);
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

Vec3 HriRenderer::robust_ramp(const Vec3& force, const Vec3& hip, const Vec3& v, const TickOut& out,
                              bool& ramped) {
  // What the plane of the tick before gives at this HIP (eqs. 2-3): a ramp starts for the
  // step the plane change causes, never for the hand's own motion since the tick before
  // (at n = 1 that restarted the ramp every tick and the force lagged the hand: an active
  // wall). A new contact compares with the target of the tick before (none: zero).
  Vec3 before = prev_target_f_;
  if (out.plane_update && ramp_ref_.valid) {
    const Vec3& n = ramp_ref_.n;
    const Vec3 d_ref = n * (-dot(n, ramp_ref_.p - hip) * inv_wpd_);  // HIP - its eq. 2 point, device [m]
    before = d_ref * -params_.stiffness_n_per_m - n * (dot(v, n) * params_.damping_n_s_per_m);
    if (dot(before, n) < 0.0) before = {};
  }
  return ramp_force(force, out.plane_update, plane_.n, before, ramped);
}

Vec3 HriRenderer::ramp_force(const Vec3& force, bool plane_update, const Vec3& fallback_dir, const Vec3& before,
                             bool& ramped) {
  // Every step of the spring-damper force that a plane creation or update causes (or the
  // first contact tick after a fault) is spread over recovery_time_s: |F| goes linearly
  // from the magnitude sent the tick before to the new target (the offset fades out,
  // never below zero), and the direction turns from the one sent the tick before to the
  // new one over the same time (turn_toward: a blend within 90 deg, a rotation beyond), so a
  // plane that turns turns the force over the ramp too (a magnitude-only ramp sent the
  // new direction at once: 106 deg in one tick on the head CT). An update that does not
  // move the target lets a ramp go on. The ramp runs on accumulated time (ramp_dt_s_:
  // this tick's period, clamped), so neither lost ticks nor one jittery period change its
  // length.
  if (params_.recovery_time_s > 0 && (plane_update || after_fault_) && !edit_tick_ &&
      norm(force - (after_fault_ ? prev_target_f_ : before)) > 0.01 * params_.force_limit_n) {
    ramp_left_s_ = params_.recovery_time_s;
    recovery_from_n_ = prev_force_mag_ - norm(force);  // offset to fade out [N]
    ramp_from_dir_ = prev_force_mag_ > 0 ? prev_force_ / prev_force_mag_ : Vec3{};
  }
  prev_target_f_ = force;
  ramped = ramp_left_s_ > 0;
  if (!ramped) return force;  // the common tick: no square root
  const double mag = norm(force);
  ramp_left_s_ -= ramp_dt_s_;
  if (ramp_left_s_ < 1e-9 * params_.recovery_time_s) ramp_left_s_ = 0;  // rounding
  const double s = ramp_left_s_ / params_.recovery_time_s;
  const double m = std::max(0.0, mag + recovery_from_n_ * s);
  const Vec3 to = mag > 0 ? force / mag : fallback_dir;
  const bool turn = dot(ramp_from_dir_, ramp_from_dir_) > 0;
  return (turn ? turn_toward(ramp_from_dir_, to, s) : to) * m;
}

void HriRenderer::restart_at(const Vec3& hip) {
  // First tick, or the first sane tick after an absurd HIP: free motion from here, no
  // plane, no ramp, no velocity history (both variants).
  clear_contact();
  vhip_ = hip;
  prev_hip_ = hip;
  started_ = true;
  vhip_value_known_ = false;
  vhip_outside_ = false;
}

bool HriRenderer::note_version(std::uint64_t version) {
  const bool changed = version_known_ && version != field_version_;
  // SampleField::changed covers the step from the version just before only: a version this
  // renderer never read (two publications within one tick) hid its box.
  version_skipped_ = changed && version != field_version_ + 1;
  field_version_ = version;
  version_known_ = true;
  return changed;
}

bool HriRenderer::edit_reaches(const FieldView& field, const Vec3& hip) const {
  const SampleField::ChangedBox& box = field.changed();
  if (!box.known || version_skipped_) return true;
  if (box.empty()) return false;
  // What this renderer read from the old snapshot lies within `reach` of the HIP, the VHIP
  // or (free motion after a scan) the scan's centre: the values at the VHIP and the held
  // plane, the planes of the tool's scan, the scan's clearance.
  double reach = params_.tool_radius_m;
  if (params_.tool_radius_m > 0 && scan_valid_) reach = std::max(reach, scan_clear_m_);
  const Vec3& sp = field.grid().spacing_m;
  const Vec3 r_idx{reach / sp.x, reach / sp.y, reach / sp.z};
  Vec3 lo = field.grid().to_index(hip), hi = lo;
  const auto take = [&](const Vec3& w) {
    const Vec3 i = field.grid().to_index(w);
    lo = {std::min(lo.x, i.x), std::min(lo.y, i.y), std::min(lo.z, i.z)};
    hi = {std::max(hi.x, i.x), std::max(hi.y, i.y), std::max(hi.z, i.z)};
  };
  take(vhip_);
  if (params_.tool_radius_m > 0 && scan_valid_) take(anchor_);
  // A sample at voxel v is read for points within one cell of it: 2 voxels to spare.
  const double a_lo[3] = {lo.x - r_idx.x, lo.y - r_idx.y, lo.z - r_idx.z};
  const double a_hi[3] = {hi.x + r_idx.x, hi.y + r_idx.y, hi.z + r_idx.z};
  for (int a = 0; a < 3; ++a) {
    // Non-finite points (a fault) compare false: treated as reached.
    if (a_hi[a] < double(box.lo[a]) - 2.0) return false;
    if (a_lo[a] > double(box.hi[a] - 1) + 2.0) return false;
  }
  return true;
}

double HriRenderer::edit_slew(Vec3& force, double mag, TickOut& out) {
  // The force VECTOR moves from the one sent the tick before toward the target by at most
  // one step (so neither |F| nor its direction can jump: a carve that tilts the surface
  // 45 degrees under a held HIP turns the force over several ticks); the slew ends on the
  // tick that reaches the target. A zero target fades the last force out along its own
  // direction (a fading contact, penetration 0).
  const double step = params_.edit_max_step_fraction * params_.force_limit_n;
  if (!(step > 0.0)) {  // a force limit <= 0 or NaN: nothing to slew toward
    edit_slewing_ = false;
    return mag;
  }
  // The direction first: at most edit_max_turn_deg from the one sent (rotated in the plane
  // of the two, the target's magnitude kept); then the vector step. Both forces lie in the
  // cone of that half-angle around the direction sent, so the step stays inside it.
  Vec3 goal = force;
  const double prev_mag = norm(prev_force_);
  bool turned = false;
  if (prev_mag > 0.0 && mag > 0.0 && params_.edit_max_turn_deg > 0.0) {
    const Vec3 a = prev_force_ / prev_mag, b = force / mag;
    const double c = std::clamp(dot(a, b), -1.0, 1.0);
    const double max_turn = params_.edit_max_turn_deg * M_PI / 180.0;
    if (std::acos(c) > max_turn) {
      const Vec3 perp = normalized_or(b - a * c, Vec3{});
      if (dot(perp, perp) > 0.0) {
        goal = (a * std::cos(max_turn) + perp * std::sin(max_turn)) * mag;
        turned = true;
      }
    }
  }
  const Vec3 gap = goal - prev_force_;
  const double g = norm(gap);
  if (!(g > step)) {
    if (!turned) {
      edit_slewing_ = false;
      return mag;
    }
    force = goal;
    return norm(force);
  }
  force = prev_force_ + gap * (step / g);  // between two forces within the limit: within it too
  if (!(mag > 0.0)) out.contact = true;    // a fading contact force, penetration 0
  return norm(force);
}

// ---- Spherical tool ----

Vec3 HriRenderer::tool_solve(const Vec3& hip) const {
  // min |x - hip| subject to n_i . (x - p_i) >= r: the optimum is the projection of the HIP
  // onto the intersection of some active subset (KKT: x = hip + sum l_j n_j, l_j >= 0);
  // every subset's projection that is feasible is a candidate, the nearest wins.
  const double r = params_.tool_radius_m;
  const int m = tool_plane_count_;
  const ToolPlane* pl = tool_planes_;
  const double tol = 1e-9;
  auto feasible = [&](const Vec3& x) {
    for (int i = 0; i < m; ++i)
      if (dot(pl[i].n, x - pl[i].p) < r - tol) return false;
    return true;
  };
  if (feasible(hip)) return hip;
  Vec3 best = hip;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (int mask = 1; mask < (1 << m); ++mask) {
    int idx[3];
    int k = 0;
    for (int i = 0; i < m && k <= 3; ++i)
      if (mask & (1 << i)) {
        if (k < 3) idx[k] = i;
        ++k;
      }
    if (k > 3) continue;  // at most 3 independent constraints in 3-D
    double b[3], l[3] = {0, 0, 0};
    for (int i = 0; i < k; ++i) b[i] = r - dot(pl[idx[i]].n, hip - pl[idx[i]].p);
    auto g = [&](int i, int j) { return dot(pl[idx[i]].n, pl[idx[j]].n); };
    if (k == 1) {
      l[0] = b[0];
    } else if (k == 2) {
      const double a = g(0, 0), c = g(0, 1), d = g(1, 1);
      const double det = a * d - c * c;
      if (!(std::abs(det) > 1e-9)) continue;
      l[0] = (b[0] * d - c * b[1]) / det;
      l[1] = (a * b[1] - c * b[0]) / det;
    } else {
      const double a00 = g(0, 0), a01 = g(0, 1), a02 = g(0, 2), a11 = g(1, 1), a12 = g(1, 2), a22 = g(2, 2);
      const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
      const double det = a00 * c00 + a01 * c01 + a02 * c02;
      if (!(std::abs(det) > 1e-9)) continue;
      const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
      l[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) / det;
      l[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) / det;
      l[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det;
    }
    bool ok = true;
    Vec3 x = hip;
    for (int i = 0; i < k; ++i) {
      if (!(l[i] >= -tol)) ok = false;
      x = x + pl[idx[i]].n * l[i];
    }
    if (!ok || !feasible(x)) continue;
    const Vec3 dx = x - hip;
    const double d2 = dot(dx, dx);
    if (d2 < best_d2) {
      best_d2 = d2;
      best = x;
    }
  }
  if (std::isfinite(best_d2)) return best;
  // No feasible subset (planes that no sphere of radius r fits between): project onto
  // the violated planes in turn, a few rounds.
  Vec3 x = hip;
  for (int round = 0; round < 8; ++round)
    for (int i = 0; i < m; ++i) {
      const double v = r - dot(pl[i].n, x - pl[i].p);
      if (v > 0) x = x + pl[i].n * v;
    }
  return x;
}

bool HriRenderer::nearest_surface(const FieldView& field, const Vec3& x, double reach, Vec3& q,
                                  Vec3& n) const {
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const Isosurface iso{params_.tau, params_.inside};
  // Newton steps along the gradient from `from`: y <- y + N e / |grad| (e the excess, N
  // outward), each at most one voxel long, at most `steps` reads; true when on the surface.
  auto newton = [&](Vec3 from, int steps, Vec3& y) {
    y = from;
    for (int k = 0; k < steps; ++k) {
      const FieldValue s = sample_trilinear(field, y);
      const double e = excess(s.value);
      const Vec3 go = iso.outward(s.gradient);
      const double gn = norm(go);
      if (!std::isfinite(s.value) || !(gn > 0) || !std::isfinite(gn)) return false;
      const double step = std::clamp(e / gn, -voxel, voxel);
      y = y + go * (step / gn);
      const Vec3 moved = y - x;
      if (dot(moved, moved) > reach * reach) return false;
      if (std::abs(step) < 1e-3 * voxel) return true;
    }
    return false;
  };
  Vec3 y;
  bool found = newton(x, 8, y);
  if (!found) {
    // March along the normal at x (inward when x is outside, outward when inside),
    // half-voxel steps within reach, then 20 bisection steps.
    const bool in = excess(sample_value(field, x)) > 0.0;
    const Vec3 n0 = outward_normal(field, x, Vec3{0.0, 0.0, 1.0});
    const Vec3 dir = in ? n0 : n0 * -1.0;
    const double h = 0.5 * voxel;
    const int steps = std::max(1, int(std::ceil(reach / h)));
    double lo = 0.0;
    for (int i = 1; i <= steps && !found; ++i) {
      const double t = std::min(reach, h * i);
      const bool inside = excess(sample_value(field, x + dir * t)) > 0.0;
      if (inside != in) {
        double hi = t;
        for (int k = 0; k < 20; ++k) {
          const double mid = 0.5 * (lo + hi);
          ((excess(sample_value(field, x + dir * mid)) > 0.0) == in ? lo : hi) = mid;
        }
        y = x + dir * (in ? hi : lo);  // the outside end of the bracket
        found = true;
      }
      lo = t;
    }
    if (!found) return false;
  }
  n = outward_normal(field, y, normalized_or(x - y, Vec3{0.0, 0.0, 1.0}));
  // A gradient path ends near, not at, the nearest point of a curved surface: twice, slide
  // to the foot of x on the tangent plane and come back to the surface (Newton again).
  for (int round = 0; round < 2; ++round) {
    const Vec3 off = x - y;
    const Vec3 tangential = off - n * dot(n, off);
    if (!(dot(tangential, tangential) > 1e-6 * voxel * voxel)) break;
    Vec3 y2;
    if (!newton(y + tangential, 4, y2)) break;
    y = y2;
    n = outward_normal(field, y, n);
  }
  q = y;
  return finite(q) && finite(n);
}

void HriRenderer::tool_rebuild_newton(const FieldView& field, const Vec3& hip) {
  // 1. The surface point nearest the proxy of the tick before gives the first plane.
  // 2. A held plane that proxy still touches (within a quarter voxel), that faces another
  //    way than every new plane (more than 15 deg) and whose wall is still there (inside a
  //    quarter voxel behind its point) is another wall of a groove or a corner: it stays
  //    (else the proxy, moved toward the HIP under the new plane alone, could cross into it).
  // 3. While the proxy moved toward the HIP under the planes so far is still closer than r
  //    to the surface, the point nearest it gives the next plane. At most three.
  const double r = params_.tool_radius_m;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const double tol = 1e-3 * voxel;
  const double reach = 1.8 * r + voxel;
  ToolPlane held[kMaxToolPlanes];
  const int held_count = tool_plane_count_;
  std::copy(tool_planes_, tool_planes_ + held_count, held);
  tool_plane_count_ = 0;
  auto add = [&](const Vec3& n, const Vec3& q) {
    for (int j = 0; j < tool_plane_count_; ++j)
      if (dot(tool_planes_[j].n, n) > 0.9999 && std::abs(dot(tool_planes_[j].n, q - tool_planes_[j].p)) < tol)
        return false;  // the same plane
    tool_planes_[tool_plane_count_++] = {n, q};
    return true;
  };
  // A point farther than r + 1 voxel from where it was searched is not the wall in
  // contact (a gradient path through a drilled cavity can end anywhere within reach).
  auto near = [&](const Vec3& from, const Vec3& q) {
    const Vec3 d = q - from;
    return dot(d, d) <= (r + voxel) * (r + voxel);
  };
  Vec3 q, n;
  if (nearest_surface(field, vhip_, reach, q, n) && near(vhip_, q)) add(n, q);
  const double cos15 = 0.9659;
  for (int i = 0; i < held_count && tool_plane_count_ < 3; ++i) {
    if (!(dot(held[i].n, vhip_ - held[i].p) < r + 0.25 * voxel)) continue;
    // ... and only where the wall is still there (an edit may have removed it).
    if (!(excess(sample_value(field, held[i].p - held[i].n * (0.25 * voxel))) > 0.0)) continue;
    bool other = true;
    for (int j = 0; j < tool_plane_count_; ++j)
      if (dot(tool_planes_[j].n, held[i].n) > cos15) other = false;
    if (other) add(held[i].n, held[i].p);
  }
  while (tool_plane_count_ > 0 && tool_plane_count_ < 3) {
    const Vec3 x = tool_solve(hip);
    bool added = false;
    if (nearest_surface(field, x, reach, q, n) && near(x, q) && dot(n, x - q) < r - tol) added = add(n, q);
    if (!added) {
      // A gradient path from x can end on a farther sheet (a crease, a thin wall): also
      // from the point of the sphere that leads toward the HIP, if it is inside.
      const Vec3 to_hip = hip - x;
      const double l = norm(to_hip);
      const Vec3 lead = l > 0 ? x + to_hip * (r / l) : x;
      if (l > 0 && excess(sample_value(field, lead)) > 0.0 && nearest_surface(field, lead, reach, q, n) &&
          near(x, q) && dot(n, x - q) < r - tol)
        added = add(n, q);
    }
    if (!added) break;  // the proxy is clear of the surface
  }
}

namespace {
/// The point of one trilinear cell's surface nearest X (surface_scan): `e` the excess at the
/// cell's corners (corner c = i + 2 j + 4 k), X and the result relative to the lower corner
/// [m], `sp` the cell's size [m]. The nearest edge crossing (an exact surface point: the
/// field is linear along an edge), then projections of X onto the patch linearised at the
/// current point (y <- X - g (e + g . (X - y)) / |g|^2, clamped to the cell, at most 10
/// rounds) from the cell point nearest X and from that crossing; a projection that lands
/// on the patch (|e| < tol |g|) and is nearer replaces the crossing.
struct CellPoint {
  Vec3 best;                                              ///< the nearest point found
  double best_d2 = std::numeric_limits<double>::infinity();  ///< its squared distance (inf: none)
  bool converged = false;                                 ///< a projection landed on the patch
  Vec3 gradient;  ///< the excess gradient [1/m] at the best point (clamped to the cell)
};
CellPoint nearest_in_cell(const double (&e)[8], const double (&xa)[3], const Vec3& sp, double tol) {
  const Vec3 X{xa[0], xa[1], xa[2]};
  // Trilinear excess and its gradient [1/m] at u in [0,1]^3 (corner c = i + 2 j + 4 k).
  auto eval = [&](const Vec3& u, Vec3& g) {
    const double x0 = 1 - u.x, y0 = 1 - u.y, z0 = 1 - u.z;
    const double e00 = e[0] * x0 + e[1] * u.x, e10 = e[2] * x0 + e[3] * u.x;
    const double e01 = e[4] * x0 + e[5] * u.x, e11 = e[6] * x0 + e[7] * u.x;
    const double e0 = e00 * y0 + e10 * u.y, e1 = e01 * y0 + e11 * u.y;
    g.x = ((e[1] - e[0]) * y0 * z0 + (e[3] - e[2]) * u.y * z0 + (e[5] - e[4]) * y0 * u.z +
           (e[7] - e[6]) * u.y * u.z) / sp.x;
    g.y = ((e10 - e00) * z0 + (e11 - e01) * u.z) / sp.y;
    g.z = (e1 - e0) / sp.z;
    return e0 * z0 + e1 * u.z;
  };
  auto clamp_u = [&](const Vec3& y) {
    return Vec3{std::clamp(y.x / sp.x, 0.0, 1.0), std::clamp(y.y / sp.y, 0.0, 1.0),
                std::clamp(y.z / sp.z, 0.0, 1.0)};
  };
  // The nearest edge crossing.
  Vec3 best;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    const int step = 1 << a;
    for (int c = 0; c < 8; ++c) {
      if (c & step) continue;
      const double ea = e[c], eb = e[c + step];
      if ((ea > 0.0) == (eb > 0.0)) continue;
      double ya[3] = {double(c & 1) * sp.x, double((c >> 1) & 1) * sp.y, double(c >> 2) * sp.z};
      ya[a] = sp[a] * (ea / (ea - eb));
      const Vec3 y{ya[0], ya[1], ya[2]};
      const Vec3 d = X - y;
      if (dot(d, d) < best_d2) {
        best_d2 = dot(d, d);
        best = y;
      }
    }
  }
  // Projections onto the linearised patch from the cell point nearest x; a component
  // held at a face of the cell (the target beyond it) stays there and the others
  // solve the linearised problem on that face.
  // Two starts: the cell point nearest x, and the nearest edge crossing (a cell may
  // hold two sheets of a saddle).
  bool converged = false;
  Vec3 g;
  const Vec3 starts[2] = {clamp_u(X), std::isfinite(best_d2) ? clamp_u(best) : clamp_u(X)};
  for (int start = 0; start < (std::isfinite(best_d2) ? 2 : 1); ++start) {
    Vec3 u = starts[start];
    for (int it = 0; it < 10; ++it) {
      const double ya[3] = {u.x * sp.x, u.y * sp.y, u.z * sp.z};
      const double ev = eval(u, g);
      double ga[3] = {g.x, g.y, g.z}, xa2[3] = {xa[0], xa[1], xa[2]};
      double g2 = dot(g, g);
      if (!(g2 > 0)) break;
      const double lx = ev + g.x * (xa[0] - ya[0]) + g.y * (xa[1] - ya[1]) + g.z * (xa[2] - ya[2]);
      for (int a = 0; a < 3; ++a) {
        const double t = xa[a] - ga[a] * lx / g2;
        const double ua = a == 0 ? u.x : (a == 1 ? u.y : u.z);
        if ((ua <= 0.0 && t < 0.0) || (ua >= 1.0 && t > sp[a])) {
          ga[a] = 0;
          xa2[a] = ya[a];
        }
      }
      g2 = ga[0] * ga[0] + ga[1] * ga[1] + ga[2] * ga[2];
      if (!(g2 > 0)) break;
      const double l2 = ev + ga[0] * (xa2[0] - ya[0]) + ga[1] * (xa2[1] - ya[1]) + ga[2] * (xa2[2] - ya[2]);
      const Vec3 next = clamp_u({xa2[0] - ga[0] * l2 / g2, xa2[1] - ga[1] * l2 / g2, xa2[2] - ga[2] * l2 / g2});
      // A fixed point: every further round would compute the same u (the rounds are a
      // function of u alone), so stopping here gives the same point in fewer rounds.
      if (next.x == u.x && next.y == u.y && next.z == u.z) break;
      u = next;
    }
    {
      const Vec3 y{u.x * sp.x, u.y * sp.y, u.z * sp.z};
      const double ev = eval(u, g);
      const double gn = norm(g);
      const Vec3 d = X - y;
      const bool on = gn > 0 && std::abs(ev) < tol * gn;
      converged = converged || on;
      if (on && dot(d, d) < best_d2) {
        best_d2 = dot(d, d);
        best = y;
      }
    }
  }
  CellPoint out;
  out.best = best;
  out.best_d2 = best_d2;
  out.converged = converged;
  if (std::isfinite(best_d2)) eval(clamp_u(best), out.gradient);
  return out;
}

}  // namespace

bool HriRenderer::surface_scan(const FieldView& field, const Vec3& x, double reach) {
  // Every cell whose box lies within `reach` of x: the trilinear field on a cell lies
  // between its corners' extremes, so the cell holds the surface exactly when its corners
  // straddle tau (a NaN corner: no surface, as everywhere in the servo). In such a cell
  // its point nearest x (nearest_in_cell). The kMaxScanPoints nearest points are kept.
  const Grid& grid = field.grid();
  const Vec3& sp = grid.spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const Vec3 ix = grid.to_index(x);
  if (!finite(ix) || !(reach > 0)) return false;
  int lo[3], n[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = int(std::floor(ix[a] - reach / sp[a]));
    n[a] = int(std::ceil(ix[a] + reach / sp[a])) - lo[a] + 1;  // samples on this axis
    if (n[a] > kScanSide || n[a] < 2) return false;
  }
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        const double v = field.value_at_index({double(lo[0] + i), double(lo[1] + j), double(lo[2] + k)});
        scan_excess_[(k * n[1] + j) * n[0] + i] = std::isfinite(v) ? float(excess(v)) : std::nanf("");
      }
  scan_count_ = 0;
  scan_clear_m_ = reach;
  const double tol = 1e-3 * voxel;
  const bool x_outside = !(excess(field.value(x)) > 0.0);
  auto keep = [&](const Vec3& q, const Vec3& n_out, double d) {
    if (scan_count_ == kMaxScanPoints) {
      int far = 0;
      for (int c = 1; c < scan_count_; ++c)
        if (scan_[c].d > scan_[far].d) far = c;
      if (!(d < scan_[far].d)) return;
      scan_[far] = {q, n_out, d};
    } else {
      scan_[scan_count_++] = {q, n_out, d};
    }
  };
  for (int ck = 0; ck + 1 < n[2]; ++ck)
    for (int cj = 0; cj + 1 < n[1]; ++cj)
      for (int ci = 0; ci + 1 < n[0]; ++ci) {
        const int c0[3] = {ci, cj, ck};
        // x relative to the cell's lower corner [m], and the cell's box distance.
        double xa[3];
        double box2 = 0;
        for (int a = 0; a < 3; ++a) {
          xa[a] = (ix[a] - double(lo[a] + c0[a])) * sp[a];
          const double out = std::max({0.0, -xa[a], xa[a] - sp[a]});
          box2 += out * out;
        }
        if (box2 > reach * reach) continue;
        double e[8];
        bool in = false, outside = false, nan = false;
        for (int c = 0; c < 8; ++c) {
          const float v = scan_excess_[((ck + (c >> 2)) * n[1] + cj + ((c >> 1) & 1)) * n[0] + ci + (c & 1)];
          nan = nan || !std::isfinite(v);
          e[c] = v;
          (v > 0.0f ? in : outside) = true;
        }
        if (nan || !in || !outside) continue;
        const CellPoint cp = nearest_in_cell(e, xa, sp, tol);
        if (!std::isfinite(cp.best_d2)) continue;
        const Vec3& best = cp.best;
        const double dist = std::sqrt(cp.best_d2);
        const Vec3& gq = cp.gradient;
        const Vec3 q = grid.to_world(
            {double(lo[0] + ci) + best.x / sp.x, double(lo[1] + cj) + best.y / sp.y, double(lo[2] + ck) + best.z / sp.z});
        // The plane's normal: toward x from an x outside (the nearest point's normal, and
        // defined at creases); the outward gradient where x is inside or on the surface.
        const Vec3 n_grad = normalized_or(gq * -1.0, normalized_or(x - q, Vec3{0.0, 0.0, 1.0}));
        const Vec3 n_out = x_outside && dist > tol ? (x - q) / dist : n_grad;
        keep(q, n_out, dist);
        // The free-motion clearance: the point found where the projections converged, else
        // the cell's box distance (a proven lower bound).
        scan_clear_m_ = std::min(scan_clear_m_, cp.converged ? dist : std::sqrt(box2));
      }
  // Nearest first (insertion sort: at most kMaxScanPoints).
  for (int a = 1; a < scan_count_; ++a)
    for (int b = a; b > 0 && scan_[b].d < scan_[b - 1].d; --b) std::swap(scan_[b], scan_[b - 1]);
  return true;
}

int HriRenderer::tool_add_uncovered(const Vec3& x, double reach, double voxel) {
  // A scanned point behind a held plane, or on it to 0.01 voxel, cannot come nearer than
  // r (less that) to a proxy the plane holds; every other point within reach adds a plane
  // through it facing x (nearest first).
  const double cover = 0.01 * voxel;
  int added = 0;
  for (int c = 0; c < scan_count_ && tool_plane_count_ < kMaxToolPlanes; ++c) {
    const ScanPoint& s = scan_[c];
    if (s.d > reach) break;
    bool covered = false;
    for (int i = 0; i < tool_plane_count_ && !covered; ++i)
      covered = dot(tool_planes_[i].n, s.q - tool_planes_[i].p) < cover;
    if (covered) continue;
    const double d = norm(x - s.q);
    const Vec3 n = d > 1e-3 * voxel && dot(x - s.q, s.n) > 0 ? (x - s.q) / d : s.n;
    tool_planes_[tool_plane_count_++] = {n, s.q};
    ++added;
  }
  return added;
}

void HriRenderer::tool_rebuild(const FieldView& field, const Vec3& hip) {
  // The planes from scans of the cells around the proxy (see the class docs); a tool too
  // large for the scan box: Newton searches (tool_rebuild_newton).
  const double r = params_.tool_radius_m;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  const double reach = r + voxel;
  Vec3 centre = vhip_;
  scan_valid_ = false;
  for (int pass = 0; pass < 3; ++pass) {
    if (!surface_scan(field, centre, reach)) {
      if (pass == 0) tool_rebuild_newton(field, hip);
      return;
    }
    if (pass == 0) tool_plane_count_ = 0;
    tool_add_uncovered(centre, reach, voxel);
    anchor_ = centre;
    scan_valid_ = true;
    const Vec3 y = tool_plane_count_ > 0 ? tool_solve(hip) : hip;
    const Vec3 moved = y - centre;
    if (dot(moved, moved) <= 0.0625 * voxel * voxel) break;
    centre = y;
  }
}

Vec3 HriRenderer::tool_tick(const FieldView& field, const Vec3& hip, bool edited, TickOut& out) {
  const double r = params_.tool_radius_m;
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  bool update = edited && (tool_plane_count_ > 0 || was_contact_);
  if (edited) scan_valid_ = false;  // the last scan's clearance was of the old snapshot
  if (tool_plane_count_ > 0 && !update) {
    bool held = false;  // does any plane hold the HIP?
    for (int i = 0; i < tool_plane_count_; ++i)
      if (dot(tool_planes_[i].n, hip - tool_planes_[i].p) < r) held = true;
    if (!held) {
      tool_plane_count_ = 0;  // clear of every plane: free motion (tested below)
    } else {
      const Vec3 slide = tool_solve(hip) - anchor_;
      // Early when the proxy is 0.2 voxel from the scan's centre: the scan covered the
      // surface within r + 1 voxel of it, and a tangent plane held over a curved (or,
      // between voxels, wavy trilinear) surface lets the sphere sink by about
      // slide^2 * curvature / 2.
      if (++c_ >= params_.plane_update_period || dot(slide, slide) > 0.04 * voxel * voxel) update = true;
    }
  }
  if (tool_plane_count_ == 0 && !update && scan_valid_) {
    // Free motion after a scan: no surface is nearer to its centre than scan_clear_m_, so
    // none is within r of a HIP that moved less than that less r (0.01 voxel to spare).
    const Vec3 moved = hip - anchor_;
    const double room = scan_clear_m_ - r - 0.01 * voxel;
    update = !(room > 0) || dot(moved, moved) > room * room;
  } else if (tool_plane_count_ == 0 && !update) {
    // Free motion: one value + gradient read at the HIP. Search only when a surface may
    // be within reach (first-order distance), or the HIP entered the object.
    const FieldValue s = sample_trilinear(field, hip);
    const double e = excess(s.value);
    const double gn = norm(s.gradient);
    if (e > 0.0) update = !(excess(sample_value(field, vhip_)) > 0.0);  // starting inside: no force
    // Where the field is flat (|e| / |grad| beyond 8 voxels: a drilled cavity, uniform
    // empty value, air) the first-order distance says nothing: search there every n ticks.
    else {
      const bool flat = !(gn > 0) ? std::isfinite(s.value) : -e > 8.0 * voxel * gn;
      update = (gn > 0 && -e < (r + voxel) * gn) || (flat && ++c_ >= params_.plane_update_period);
    }
  }
  if (update) {
    ToolPlane kept[kMaxToolPlanes];
    const int kept_count = tool_plane_count_;
    std::copy(tool_planes_, tool_planes_ + kept_count, kept);
    tool_rebuild(field, hip);
    if (tool_plane_count_ == 0 && kept_count > 0 && excess(sample_value(field, hip)) > 0.0) {
      // No surface within reach of the proxy while the HIP is inside: material removed
      // around the tool (a drill), or a noisy scan. The proxy goes toward the HIP up to the
      // surface on the way (first crossing of the segment; the plane there, the centre r
      // before it); failing that, the planes of the tick before still hold the HIP.
      Vec3 q;
      scan_valid_ = false;  // these planes are not the scan's
      if (!(excess(sample_value(field, vhip_)) > 0.0) && first_crossing(field, vhip_, hip, q)) {
        const Vec3 n = outward_normal(field, q, normalized_or(vhip_ - hip, kept[0].n));
        tool_planes_[0] = {n, q};
        tool_plane_count_ = 1;
      } else {
        std::copy(kept, kept + kept_count, tool_planes_);
        tool_plane_count_ = kept_count;
      }
    }
    c_ = 0;
    if (!scan_valid_) anchor_ = tool_solve(hip);
    out.plane_update = true;
  }
  const Vec3 x = tool_plane_count_ > 0 ? tool_solve(hip) : hip;
  vhip_ = x;
  const Vec3 push = (x - hip) * inv_wpd_;  // device [m]
  const double depth = norm(push);
  if (!(depth > 0.0)) {
    prev_target_f_ = {};
    ramp_from_dir_ = {};
    ramp_left_s_ = 0;
    return {};
  }
  const Vec3 u = push / depth;
  Vec3 force = u * (params_.stiffness_n_per_m * depth - params_.damping_n_s_per_m * dot(v_filt_, u));
  if (dot(force, u) < 0.0) force = {};  // a wall pushes, never pulls
  bool ramped = false;
  if (params_.recovery_time_s > 0) force = ramp_force(force, out.plane_update, u, prev_target_f_, ramped);
  out.contact = true;
  out.penetration_m = norm(hip - x);
  return force;
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

// The robust tick from the plain state. Every way out that is not a common tick is a call in
// tail position (tick_robust_full, general_tick, the free tick's read, the force limit), so
// the common ticks keep their values in registers the calls may clobber: tick() saves one
// register where it saved six, and builds the HriTick from registers.
[[gnu::always_inline]] inline HriTick HriRenderer::quick_tick(const FieldView& field, const Vec3& hip, double dt_s) {
  // The plain state: the robust tick's fault, restart, edit, ramp, release and slew branches
  // cannot act (each of those ticks takes the full path). In it after_fault_ is false,
  // lost_s_ is 0, none of ramp_left_s_, release_left_s_ and recovery_ticks_left_ is above 0
  // (every reader tests that), version_known_ is true where edits are tracked, and sliding_
  // is false (no friction): the full path's stores of them would change nothing.
  if (!plain_) return tick_robust_full(field, hip, dt_s);
  if (params_.edit_max_step_fraction > 0 && field.version() != field_version_) return tick_robust_full(field, hip, dt_s);
  const double dt = (dt_s > 0 && std::isfinite(dt_s)) ? dt_s : dt_nominal_s_;
  const double elapsed = dt;  // + lost_s_ (0)
  // Sane and within reach (tick_robust_full's fault test): a non-finite HIP fails the
  // comparison, as does one so far out that the squares overflow (quick_ok_: a finite reach^2).
  const Vec3 from_centre = hip - field.grid().centre_m();
  if (!(dot(from_centre, from_centre) <= params_.max_reach_m * params_.max_reach_m))
    return tick_robust_full(field, hip, dt_s);
  const bool holding = plane_.valid;
  if (holding) {
    const Vec3 moved = hip - prev_hip_;
    const double max_move = params_.max_speed_m_s * params_.world_per_device * elapsed;
    if (dot(moved, moved) > max_move * max_move) return tick_robust_full(field, hip, dt_s);  // a jump
  } else if (was_contact_ && params_.recovery_time_s > 0 && prev_force_mag_ > 0.01 * params_.force_limit_n) {
    return tick_robust_full(field, hip, dt_s);  // a release fade would start
  }
  // tick_robust_full's prologue for this state (version_skipped_ is read on an edit tick only,
  // after note_version sets it; ramp_dt_s_ where a ramp or a release fade can start:
  // tick_general).
  edit_tick_ = false;
  filter_velocity(hip, elapsed);
  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min(sp.x, std::min(sp.y, sp.z));  // (std::min({...}) went through the stack)
  // The two ticks written out, not short_tick + finish_robust: calling those here measured
  // HRI/Avila 0.09-0.11 higher on the four table1 strokes (bench_hri_tick, 6 alternated
  // rounds), higher than with no quick tick at all.
  if (holding) {
    // short_tick's contact tick and contact_force's robust frictionless force: g = N . (p - HIP)
    // > 0 is the HIP behind the plane (N . (HIP - p) = -g exactly), the proxy HIP + g N (eq. 2).
    const Vec3& n = plane_.n;
    const double g = dot(n, plane_.p - hip);
    const Vec3 to = hip + n * g;
    const Vec3 slide = to - anchor_, move = to - vhip_;
    if (!(g > 0.0) || !(c_ + 1 < params_.plane_update_period) || dot(slide, slide) > 0.25 * voxel * voxel ||
        !(dot(move, move) <= 0.0625 * voxel * voxel)) {
      ramp_dt_s_ = std::min(dt, 2.0 * dt_nominal_s_);
      return general_tick(field, hip, voxel, elapsed, false, 0.0);
    }
    const double m = params_.stiffness_n_per_m * (g * inv_wpd_) - params_.damping_n_s_per_m * dot(v_filt_, n);
    const bool push = !(m <= 0.0);
    const Vec3 force = push ? n * m : Vec3{};
    const double mag = push ? m : 0.0;
    // Out of line wherever limit_force could act: |F| at or above the limit, or not a
    // number (an infinite |F| under an infinite limit is a fault too: not inf < inf).
    if (!(mag < params_.force_limit_n)) return quick_contact_limited(hip, to, g, force, mag);
    quick_contact_state(hip, to, force, force, mag);
    TickOut out;
    out.contact = true;
    out.penetration_m = std::abs(g);
    out.force_n = force;
    return result(out, plane_);
  }
  // Free motion: short_tick's free tick. In the outside cell of the last read nothing is
  // read: no point of the cell is inside, so the read would say outside; nor can a long step
  // cross the surface: the VHIP is the HIP of the tick before, in the cell too (every tick
  // since the cell was read was a free tick in it), and so is the segment between them.
  const bool in_cell = cell_valid_ && field.storage() == cell_storage_ && hip.x >= cell_lo_m_.x &&
                       hip.y >= cell_lo_m_.y && hip.z >= cell_lo_m_.z && hip.x <= cell_hi_m_.x &&
                       hip.y <= cell_hi_m_.y && hip.z <= cell_hi_m_.z;
  if (!(in_cell && cell_outside_)) return free_read_tick(field, hip, voxel, dt, in_cell);
  ++reads_skipped_;
  quick_free_state(hip, false, 0.0);
  return result(TickOut{}, plane_);
}

// finish_robust's state for a quick contact tick: the proxy `to`, the target and the force
// sent (limited), |F| sent.
[[gnu::always_inline]] inline void HriRenderer::quick_contact_state(const Vec3& hip, const Vec3& to, const Vec3& target,
                                                                    const Vec3& sent, double mag) {
  ++c_;
  vhip_ = to;
  if (params_.recovery_time_s > 0) prev_target_f_ = target;  // ramp_force with no trigger and no ramp running
  prev_hip_ = hip;
  prev_force_mag_ = mag;
  prev_force_ = sent;
  was_contact_ = true;
  vhip_value_known_ = false;
  vhip_outside_ = false;
  vhip_value_ = 0.0;
}

// finish_robust's state for a quick free tick (no edit, no release starting).
[[gnu::always_inline]] inline void HriRenderer::quick_free_state(const Vec3& hip, bool have_f_hip, double f_hip) {
  vhip_ = hip;
  prev_target_f_ = {};
  prev_hip_ = hip;
  prev_force_mag_ = 0;
  prev_force_ = {};
  was_contact_ = false;
  vhip_value_known_ = have_f_hip;
  vhip_value_ = f_hip;
  vhip_outside_ = !have_f_hip;
}

[[gnu::noinline]] HriTick HriRenderer::quick_contact_limited(const Vec3& hip, const Vec3& to, double g, Vec3 force,
                                                             double mag) {
  TickOut out;
  out.contact = true;
  out.penetration_m = std::abs(g);
  const Vec3 target = force;
  limit_force(force, mag, out);
  quick_contact_state(hip, to, target, force, mag);
  out.force_n = force;
  return result(out, plane_);
}

[[gnu::noinline]] HriTick HriRenderer::free_read_tick(const FieldView& field, const Vec3& hip, double voxel, double dt,
                                                      bool in_cell) {
  const double f_hip = sample_value(field, hip);
  if (excess(f_hip) > 0.0 || long_step(field, vhip_, hip)) {
    ramp_dt_s_ = std::min(dt, 2.0 * dt_nominal_s_);
    return general_tick(field, hip, voxel, dt, true, f_hip);
  }
  if (!in_cell && params_.edit_max_step_fraction > 0) {
    // A new cell: outside if its largest corner excess is below zero by more than the
    // rounding of the blend (1e-9 of the largest corner or tau).
    double lo = 0, hi = 0;
    cell_valid_ = field.cell_range(hip, cell_lo_m_, cell_hi_m_, lo, hi);
    const double e_max = std::max(excess(lo), excess(hi));
    const double scale = std::max({std::abs(lo), std::abs(hi), std::abs(params_.tau)});
    cell_outside_ = e_max + 1e-9 * scale < 0.0;
    cell_storage_ = field.storage();
  }
  quick_free_state(hip, true, f_hip);
  return result(TickOut{}, plane_);
}

// The state in which quick_tick's ticks are tick_robust_full's: a configuration it covers
// (quick_ok_), started, no fault, restart, edit, ramp, release nor slew running. The quick
// ticks keep it; the paths that can change it (tick_general, tick_robust_full) set plain_
// from it when they end.
bool HriRenderer::plain_state() const {
  return quick_ok_ && started_ && !resync_ && vel_valid_ && lost_s_ == 0.0 && !after_fault_ && !edit_slewing_ &&
         !(ramp_left_s_ > 0) && !(release_left_s_ > 0) && recovery_ticks_left_ <= 0 &&
         (version_known_ || !(params_.edit_max_step_fraction > 0));
}

[[gnu::noinline]] HriTick HriRenderer::general_tick(const FieldView& field, const Vec3& hip, double voxel,
                                                    double elapsed, bool have_f_hip, double f_hip) {
  TickOut out;
  tick_general(field, hip, voxel, elapsed, false, false, have_f_hip, f_hip, out);
  return result(out, plane_);
}

// The robust tick is quick_tick, inlined: a contact tick with no update due and a free
// tick that reads nothing then make no call (a call to it added a call, a return and a copy
// of the HriTick to every tick).
HriTick HriRenderer::tick(const FieldView& field, const Vec3& hip, double dt_s) {
  return params_.variant == Variant::kPaper ? tick_paper(field, hip) : quick_tick(field, hip, dt_s);
}

// Out of line: the quick tick above then compiles as a small function.
[[gnu::noinline]] HriTick HriRenderer::tick_robust_full(const FieldView& field, const Vec3& hip, double dt_s) {
  const HriTick t = tick_robust_full_body(field, hip, dt_s);
  plain_ = plain_state();
  return t;
}

HriTick HriRenderer::tick_robust_full_body(const FieldView& field, const Vec3& hip, double dt_s) {
  TickOut out;
  cell_valid_ = false;
  const double dt = (dt_s > 0 && std::isfinite(dt_s)) ? dt_s : dt_nominal_s_;
  const double elapsed = dt + lost_s_;  // since the last sane tick [s]
  const bool sane = finite(hip);
  const Vec3 from_centre = hip - field.grid().centre_m();
  const bool absurd = sane && dot(from_centre, from_centre) > params_.max_reach_m * params_.max_reach_m;
  // An implausible jump while a plane is held: the contact state means nothing any more.
  auto moved_too_far = [&]() {
    const Vec3 moved = hip - prev_hip_;
    const double max_move = params_.max_speed_m_s * params_.world_per_device * elapsed;
    return dot(moved, moved) > max_move * max_move;
  };
  const bool jump = sane && !absurd && started_ && !resync_ && plane_.valid && moved_too_far();
  if (!sane || absurd || jump) {  // a device fault: send nothing
    out.fault = true;
    resync_ = resync_ || absurd || jump;
    vel_valid_ = false;  // the velocity estimate restarts at the next sane HIP
    lost_s_ = elapsed;
    vhip_value_known_ = false;
    vhip_outside_ = false;
    prev_force_mag_ = 0;
    prev_target_f_ = {};
    recovery_ticks_left_ = 0;
    ramp_left_s_ = 0;
    after_fault_ = true;  // the force resumes from 0: the next contact tick ramps
    edit_slewing_ = false;  // zero force was sent: an edit slew ends here
    release_left_s_ = 0;    // and a release fade
    prev_force_ = {};
    return result(out, plane_);
  }
  lost_s_ = 0;
  ramp_dt_s_ = std::min(dt, 2.0 * dt_nominal_s_);  // recovery ramp: this tick's period [s]
  if (!started_ || resync_) restart_at(hip);
  // Edits: a new snapshot version. Nothing read from the old snapshot
  // (the VHIP's cached value, the held plane's |grad|) is used on it.
  const bool edited = params_.edit_max_step_fraction > 0 && note_version(field.version()) && edit_reaches(field, hip);
  bool covered_free_vhip = false;  // a free VHIP outside in the old snapshot: a contact point now
  if (edited) {
    covered_free_vhip = !plane_.valid && ((vhip_value_known_ && !(excess(vhip_value_) > 0.0)) || vhip_outside_);
    vhip_value_known_ = false;
    vhip_outside_ = false;
    plane_grad_norm_ = 0;
    ramp_left_s_ = 0;  // the edit slew takes a running recovery ramp over
  }
  edit_tick_ = edited;
  if (vel_valid_) {
    filter_velocity(hip, elapsed);
  } else {
    v_filt_ = {};
  }
  vel_valid_ = true;

  const Vec3& sp = field.grid().spacing_m;
  const double voxel = std::min({sp.x, sp.y, sp.z});
  if (params_.tool_radius_m > 0.0) {
    const Vec3 force = tool_tick(field, hip, edited, out);
    finish_robust(hip, force, edited, false, 0.0, out);
    return result(out, reported_plane());
  }
  // The HIP's value is read only when the method needs it.
  bool have_f_hip = false;
  double f_hip = 0.0;
  if (!edited && params_.short_way && short_tick(field, hip, voxel, elapsed, have_f_hip, f_hip, out))
    return result(out, plane_);
  tick_general(field, hip, voxel, elapsed, edited, covered_free_vhip, have_f_hip, f_hip, out);
  return result(out, plane_);
}

VirtualPlane HriRenderer::reported_plane() const {
  if (!(params_.tool_radius_m > 0.0)) return plane_;
  if (tool_plane_count_ == 0) return {};
  return {tool_planes_[0].n, tool_planes_[0].p, true};
}

[[gnu::always_inline]] inline void HriRenderer::adopt_plane(const VirtualPlane& pl, const Vec3& hip, TickOut& out) {
  plane_ = pl;
  plane_grad_norm_ = last_grad_norm_;
  anchor_ = hip + pl.n * dot(pl.n, pl.p - hip);  // eq. 2 on the new plane
  c_ = 0;
  out.plane_update = true;
}

[[gnu::always_inline]] inline void HriRenderer::hold_hip_inside(const FieldView& field, const Vec3& hip, double e_hip,
                                                                const VirtualPlane& held, double held_grad_norm,
                                                                double voxel, TickOut& out) {
  auto behind = [&](const VirtualPlane& pl) { return pl.valid && dot(pl.n, hip - pl.p) < 0.0; };
  Vec3 p;
  const double gn = norm(sample_trilinear(field, hip).gradient);
  const Vec3 n_prev = held.valid ? held.n : Vec3{0.0, 0.0, 1.0};
  if (surface_from(field, hip, e_hip, gn, p)) adopt_plane(plane_at(field, p, hip), hip, out);
  if (!behind(plane_)) {
    VirtualPlane pl;
    pl.n = outward_normal(field, hip, n_prev);
    if (!(dot(pl.n, n_prev) > 0.0)) pl.n = n_prev;  // never toward a far side
    pl.p = hip + pl.n * (gn > 0 ? std::clamp(e_hip / gn, 1e-3 * voxel, 4.0 * voxel) : 0.25 * voxel);
    pl.valid = finite(pl.p) && finite(pl.n);
    if (behind(pl)) {
      last_grad_norm_ = gn;
      adopt_plane(pl, hip, out);
    }
  }
  if (!behind(plane_) && behind(held)) {
    adopt_plane(held, hip, out);
    plane_grad_norm_ = held_grad_norm;
  }
}

[[gnu::always_inline]] inline bool HriRenderer::reached_through_material(const FieldView& field, const Vec3& hip,
                                                                         const VirtualPlane& held, double held_grad_norm,
                                                                         double voxel, const double* f_vhip) const {
  const Vec3 to = hip + plane_.n * dot(plane_.n, plane_.p - hip);
  const double gn = plane_grad_norm_ > 0 ? plane_grad_norm_ : held_grad_norm;
  // A plane facing away from the held one is reached through any material at all.
  const double depth = dot(plane_.n, held.n) < 0.0 ? 0.0 : 0.05 * voxel;
  // The same answer without the 7 reads where the segment lies in one cell (its median
  // length is 0.04 voxel on the head CT): no point of it can be deeper than the VHIP's
  // excess plus the most the value changes along it (FieldView::change_bound_in_cell; 1e-12
  // of tau for the rounding of the excess).
  if (f_vhip && gn > 0 &&
      excess(*f_vhip) + field.change_bound_in_cell(vhip_, to) + 1e-12 * std::abs(params_.tau) <= depth * gn)
    return false;
  bool through = false;
  FieldView::Segment seg(field, vhip_, to);
  for (int i = 1; i <= 7 && !through && gn > 0; ++i) {
    const double e = excess(seg.value(i / 8.0));
    through = e > depth * gn;
  }
  return through;
}

// Out of line: the common ticks above (the short way) then compile as a small function.
[[gnu::noinline]] void HriRenderer::tick_general(const FieldView& field, const Vec3& hip, double voxel,
                                                 double elapsed, bool edited, bool covered_free_vhip,
                                                 bool have_f_hip, double f_hip, TickOut& out) {
  cell_valid_ = false;
  auto hip_excess = [&]() {
    if (!have_f_hip) {
      f_hip = sample_value(field, hip);
      have_f_hip = true;
    }
    return excess(f_hip);
  };
  auto set_plane = [&](const VirtualPlane& pl) { adopt_plane(pl, hip, out); };
  // The VHIP's value: in free motion the VHIP is the HIP of the tick before, whose
  // value that tick read (cached), so free motion costs one sample per tick.
  // The VHIP does not move before the force is computed: one read serves every rule.
  bool have_f_vhip = vhip_value_known_;
  double f_vhip_now = vhip_value_;
  auto vhip_value = [&]() {
    if (!have_f_vhip) {
      f_vhip_now = sample_value(field, vhip_);
      have_f_vhip = true;
    }
    return f_vhip_now;
  };
  // Free motion or in front of a plane: did the segment VHIP -> HIP enter the object?
  auto entry_test = [&](bool holding) {
    Vec3 p;
    if (hip_excess() > 0.0) {
      const double f_vhip = vhip_value();
      // In contact (a plane held) the VHIP is the contact point even when embedded:
      // compute_plane searches the surface from it. In free motion both ends inside
      // means no force (starting inside, §3.1).
      if (holding || !(excess(f_vhip) > 0.0)) set_plane(compute_plane(field, f_vhip, f_hip, hip));
      else plane_.valid = false;
    } else if (long_step(field, vhip_, hip) && !(excess(vhip_value()) > 0.0) &&
               first_crossing(field, vhip_, hip, p)) {
      set_plane(plane_at(field, p, hip));  // a long step through a thin wall
    } else {
      plane_.valid = false;
    }
  };

  const bool holding = plane_.valid;
  const VirtualPlane held = plane_;  // the plane of the tick before (god-object fallback)
  const double held_grad_norm = plane_grad_norm_;
  if (holding) {
    if (!(dot(plane_.n, hip - plane_.p) < 0.0)) {
      entry_test(true);  // in front of the held plane: not in contact with it
    } else {
      // Behind the plane: no sample unless an update is due (every n ticks, or early
      // when the VHIP would slide more than half a voxel from where the plane was made).
      auto slid_far = [&]() {
        const Vec3 slide = hip + plane_.n * dot(plane_.n, plane_.p - hip) - anchor_;
        return dot(slide, slide) > 0.25 * voxel * voxel;
      };
      if (++c_ >= params_.plane_update_period || slid_far() || edited) {
        c_ = 0;
        Vec3 p;
        if (hip_excess() > 0.0) {
          // HIP inside (VHIP outside, or embedded: compute_plane searches from it).
          set_plane(compute_plane(field, vhip_value(), f_hip, hip));
        } else {
          // HIP outside but behind the plane. Start just in front of the VHIP (it may sit
          // a hair inside the near surface): if the segment enters the object, the HIP
          // left through a far side and the near surface still holds it.
          const Vec3 a = vhip_ + plane_.n * (0.1 * voxel);
          const double f_a = sample_value(field, a);
          if (excess(f_a) > 0.0) {
            set_plane(compute_plane(field, vhip_value(), f_a, hip));  // embedded
          } else if (first_crossing(field, a, hip, p, 0.2)) {
            // (fifth-voxel steps: on coarse voxels the trilinear inside of a plate one
            // voxel thick can be thinner than half a voxel, and the half-voxel march
            // stepped over it: the plane was dropped with the HIP past the far face)
            set_plane(plane_at(field, p, hip));
          } else {
            plane_.valid = false;  // the surface curved away: the HIP is really outside
          }
        }
      }
    }
  } else {
    entry_test(covered_free_vhip);
  }
  // While in contact, a HIP inside the object is never left in front of the plane (a
  // concave corner or a rough surface, where the VHIP is embedded): the contact goes on
  // at the surface found from the HIP by the bounded first-order search; failing that,
  // on a plane along the outward normal at the HIP (never facing away from the held
  // plane) at the first-order depth e / |grad| (at most 4 voxels); failing that, on the
  // plane of the tick before if the HIP is behind it.
  auto behind = [&](const VirtualPlane& pl) { return pl.valid && dot(pl.n, hip - pl.p) < 0.0; };
  if (holding && have_f_hip && excess(f_hip) > 0.0 && !behind(plane_))
    hold_hip_inside(field, hip, excess(f_hip), held, held_grad_norm, voxel, out);
  // God-object: the proxy moves on the surface, never through the object. A new plane
  // whose contact point (eq. 2) is reached from the VHIP of the tick before only through
  // material (a point of the segment more than 0.05 voxel deep, first order, at 7 interior
  // points) lies on another sheet: the far face of a thin plate, the other side of a
  // tapering edge on coarse voxels (a plane there pushed the HIP through at 1.5 N). The
  // held plane stays while the HIP is behind it. Not on edit ticks (the material moved),
  // nor from a VHIP now inside (material added under it, or a shallow embedding: the
  // segment starts in material by right).
  if (holding && out.plane_update && !edited && plane_.valid && behind(held) &&
      (dot(plane_.n, held.n) < 0.9999 || std::abs(dot(held.n, plane_.p - held.p)) > 1e-3 * voxel) &&
      !(excess(vhip_value()) > 0.0)) {
    // The VHIP's value for the bound: read from this snapshot, or cached from the tick
    // before where edits are tracked (an edit that reaches the VHIP makes this an edit tick).
    const bool fresh = !vhip_value_known_ || params_.edit_max_step_fraction > 0;
    if (reached_through_material(field, hip, held, held_grad_norm, voxel, fresh ? &f_vhip_now : nullptr)) {
      set_plane(held);
      plane_grad_norm_ = held_grad_norm;
    }
  }

  if (holding && !edited) keep_proxy_outside(field, hip, held, voxel, have_f_vhip ? &f_vhip_now : nullptr, out);

  Vec3 force;
  if (plane_.valid && dot(plane_.n, hip - plane_.p) < 0.0) {
    ramp_ref_ = holding ? held : VirtualPlane{};
    force = contact_force(field, hip, v_filt_, elapsed, out);
  } else {
    vhip_ = hip;
    sliding_ = false;
    recovery_ticks_left_ = 0;
    ramp_left_s_ = 0;
    prev_target_f_ = {};
    out.force_mag = 0.0;  // no force: no square root
  }
  finish_robust(hip, force, edited, have_f_hip, f_hip, out);
  plain_ = plain_state();
}

[[gnu::always_inline]] inline bool HriRenderer::short_tick(const FieldView& field, const Vec3& hip, double voxel,
                                                           double elapsed, bool& have_f_hip, double& f_hip,
                                                           TickOut& out) {
  // The two common ticks, by the same arithmetic as the robust tick's general path (so the
  // same bits), each point computed once: behind a held plane with no update due and a
  // proxy move that keep_proxy_outside does not check (every rule of the general path
  // that could act needs an update, a sample or a long move); free motion with the HIP
  // outside on a step too short for a thin wall.
  if (plane_.valid) {
    if (!(dot(plane_.n, hip - plane_.p) < 0.0) || !(c_ + 1 < params_.plane_update_period)) return false;
    const Vec3 to = hip + plane_.n * dot(plane_.n, plane_.p - hip);  // eq. 2: the proxy this tick
    const Vec3 slide = to - anchor_, move = to - vhip_;
    if (dot(slide, slide) > 0.25 * voxel * voxel || !(dot(move, move) <= 0.0625 * voxel * voxel)) return false;
    ++c_;
    const Vec3 force = contact_force(field, hip, v_filt_, elapsed, out);
    finish_robust(hip, force, false, false, 0.0, out);
    return true;
  }
  f_hip = sample_value(field, hip);
  have_f_hip = true;
  if (excess(f_hip) > 0.0 || long_step(field, vhip_, hip)) return false;
  vhip_ = hip;
  sliding_ = false;
  recovery_ticks_left_ = 0;
  ramp_left_s_ = 0;
  prev_target_f_ = {};
  out.force_mag = 0.0;  // no force: no square root
  finish_robust(hip, Vec3{}, false, true, f_hip, out);
  return true;
}

bool HriRenderer::path_through(const FieldView& field, const Vec3& a, const Vec3& b, double e_a, double voxel,
                               Vec3& p) const {
  // Steps of a fifth voxel, and at least 64 per segment (a tapered tip's inside is a sliver).
  const double len = norm(b - a);
  if (!std::isfinite(len) || !(len > 0.0)) return false;
  const int steps = int(std::clamp(std::ceil(len / (0.2 * voxel)), 64.0, 256.0));
  const double dt = 1.0 / steps;  // the march's t = i dt (a product, not a division, per sample)
  auto at = [&](double t) { return a + (b - a) * t; };
  // Reads along the segment (FieldView::Segment): each cell's cubic along the line is loaded
  // once, and the march reads each cell about five times.
  FieldView::Segment seg(field, a, b);
  auto e_at = [&](double t) { return excess(seg.value(t)); };
  // The entry in (lo, hi], lo outside and hi inside: 20 bisection steps.
  auto entry = [&](double lo, double hi) {
    bisect(lo, hi, 20, [&](double m) { return !(e_at(m) > 0.0); });
    return lo;
  };
  const double deeper = e_a > 0.0 ? 2.0 * e_a : 0.0;
  bool out_seen = !(e_a > 0.0);
  double lo = 0.0;
  for (int i = 1; i <= steps; ++i) {
    const double e = e_at(i * dt);
    if (!(e > 0.0)) {
      out_seen = true;
      lo = i * dt;
      continue;
    }
    if (!out_seen && !(e > deeper)) continue;  // still leaving an embedded start
    // Entered material (or went deeper than the start). One that comes out again passed
    // through it. A path that ends in material at its deepest point ends on a plane held
    // over a curved surface (a chord): the embedded-VHIP search brings it out; one that
    // was deeper than twice its end's excess went through a plate to the far face.
    int j = i;
    double deepest = e, e_end = e;
    while (j < steps && (e_end = e_at((j + 1) * dt)) > 0.0) {
      ++j;
      deepest = std::max(deepest, e_end);
    }
    if (j == steps && !(deepest > 2.0 * e_end)) return false;
    p = at(out_seen ? entry(lo, i * dt) : 0.0);
    return true;
  }
  return false;
}

void HriRenderer::keep_proxy_outside(const FieldView& field, const Vec3& hip, const VirtualPlane& held,
                                     double voxel, const double* f_vhip, TickOut& out) {
  // Where the proxy goes this tick: onto the plane (eq. 2, frictionless) or to the HIP.
  const bool behind = plane_.valid && dot(plane_.n, hip - plane_.p) < 0.0;
  const Vec3 to = behind ? hip + plane_.n * dot(plane_.n, plane_.p - hip) : hip;
  const Vec3 move = to - vhip_;
  // Sliding on a held plane moves the proxy less than a quarter voxel per tick; only a
  // longer move (a plane update, a drop, a long free step) is checked.
  if (!(dot(move, move) > 0.0625 * voxel * voxel)) return;
  // The path enters material after leaving it, or goes deeper than an embedded VHIP is
  // (whether the HIP is inside or not: in a rib one or two voxels thick the HIP inside is
  // nearer the far face, and the plane found from it puts the proxy there). Or, with the
  // HIP outside, the path leaves an embedded VHIP against the held normal: the HIP came
  // out through the far side. With the HIP inside, a proxy that leaves an embedded VHIP
  // against the held normal (and through no material) follows the surface the HIP presses
  // under (on the noisy head CT the plane found from the HIP lies one to three voxels
  // below a bump's contact point): held back at the bump, it stepped the force vector by
  // 0.18 N (5.6 % of the limit) per tick.
  const bool hip_inside = excess(sample_value(field, hip)) > 0.0;
  const double e0 = excess(f_vhip ? *f_vhip : sample_value(field, vhip_));
  Vec3 p;
  const bool out_far = !hip_inside && e0 > 0.0 && held.valid && dot(move, held.n) < -0.25 * voxel;
  if (!path_through(field, vhip_, to, e0, voxel, p) && !out_far) return;
  if (e0 > 0.0 && (out_far || dot(p - vhip_, p - vhip_) == 0.0)) {
    // Through from an embedded VHIP: the proxy comes out to the surface along the held normal.
    const double gn = norm(sample_trilinear(field, vhip_).gradient);
    Vec3 q;
    if (held.valid && surface_from(field, vhip_, e0, gn, q, &held.n)) p = q;
  }
  // The proxy would pass through material: it stays at p, held there by the surface's
  // plane there (unless it faces away from the held one) or else the held plane's normal,
  // if the HIP is behind it and sliding on it enters no material nor goes back through the
  // held plane; else by the plane through p facing the HIP.
  const double e_p = excess(sample_value(field, p));
  auto holds = [&](const VirtualPlane& c) {
    Vec3 again;
    const Vec3 slid = hip + c.n * dot(c.n, c.p - hip);
    return c.valid && dot(c.n, hip - c.p) < 0.0 && !(held.valid && dot(slid - p, held.n) < -0.25 * voxel) &&
           !path_through(field, p, slid, e_p, voxel, again);
  };
  VirtualPlane pl = plane_at(field, p, hip);
  const double gn_pl = last_grad_norm_;
  if (held.valid && !(dot(pl.n, held.n) > 0.0)) pl.valid = false;
  if (!holds(pl)) {
    pl.p = p;
    pl.n = held.valid ? held.n : Vec3{};
    pl.valid = held.valid;
    if (!holds(pl)) {
      pl.n = normalized_or(p - hip, plane_.valid ? plane_.n : Vec3{0.0, 0.0, 1.0});
      pl.valid = finite(pl.n) && finite(pl.p) && dot(pl.n, hip - pl.p) < 0.0;
    }
  }
  if (!pl.valid) return;
  plane_ = pl;
  plane_grad_norm_ = gn_pl;
  anchor_ = p;
  c_ = 0;
  out.plane_update = true;
}

[[gnu::always_inline]] inline void HriRenderer::finish_robust(const Vec3& hip, Vec3 force, bool edited,
                                                              bool have_f_hip, double f_hip, TickOut& out) {
  after_fault_ = false;
  // |F|: known where contact_force took the scalar form, else one square root.
  double mag = out.force_mag >= 0.0 ? out.force_mag : norm(force);
  limit_force(force, mag, out);
  const bool in_contact = out.contact;  // a plane held the HIP (not an edit's fade-out)
  // Release fade: contact ends with force on (a plane update found the surface curved away
  // under a HIP still behind the held plane, a drilled-away wall): the force sent the tick
  // before fades out along its own direction over recovery_time_s (contact, penetration 0)
  // instead of dropping to zero in one tick. A new contact ends the fade (its ramp starts
  // from the force sent); an edit slew takes it over.
  if (in_contact || out.fault || edit_slewing_ || edited || !(params_.recovery_time_s > 0)) {
    release_left_s_ = 0;
  } else if (was_contact_ && prev_force_mag_ > 0.01 * params_.force_limit_n) {
    release_left_s_ = params_.recovery_time_s;
    release_from_ = prev_force_;
  }
  if (release_left_s_ > 0) {
    release_left_s_ -= ramp_dt_s_;
    if (release_left_s_ < 1e-9 * params_.recovery_time_s) release_left_s_ = 0;  // rounding
    force = release_from_ * (release_left_s_ / params_.recovery_time_s);
    mag = norm(force);
    out.contact = true;
    out.penetration_m = 0;
  }
  if (edited) edit_slewing_ = true;
  if (edit_slewing_) {
    if (out.fault) edit_slewing_ = false;
    else mag = edit_slew(force, mag, out);
  }
  prev_hip_ = hip;
  prev_force_mag_ = mag;
  prev_force_ = force;
  was_contact_ = in_contact;
  vhip_value_known_ = !in_contact && have_f_hip;  // then VHIP = HIP, whose value was read
  vhip_outside_ = false;
  vhip_value_ = f_hip;
  out.force_n = force;
}

}  // namespace isotouch::servo
