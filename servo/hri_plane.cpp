// hri_plane.cpp - eq. 1, the virtual plane N . (x - p) = 0: p where the segment VHIP -> HIP
// crosses tau (Figure 2's LinearInterpolation, t clamped to [0, 1]) and N = SurfaceNormal(p)
// (the paper: central differences; here any NormalSource, the paper variant always central
// differences). Beside them the robust variant's departures in finding the plane (hri.h,
// Variant::kRobust), each for a fault a user would feel: the secant and bisection options
// for p; a shallow embedding stepped out; an embedded VHIP (Figure 5b, where the linear rule
// would extrapolate) brought to the surface by a bounded search (surface_from); the first
// crossing on a long segment (a thin wall stepped over: first_crossing); the normal on thin
// structures (the blended gradient samples of a plate's two faces cancel); a proxy path
// through material (path_through, for keep_proxy_outside in hri_robust.cpp).

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "isotouch/servo/sampling.h"

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
}  // namespace

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

}  // namespace isotouch::servo
