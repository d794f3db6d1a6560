// hri_robust.cpp - the robust tick (Variant::kRobust, the default): Figure 2 with the
// departures hri.h lists, each for a fault a user would feel: the plane recomputed every n
// ticks as §3.2 says (c incremented first; and early when the VHIP would slide more than
// half a voxel); samples read only when a rule needs them; an entry test in front of a held
// plane; the god-object rules (a HIP inside is never left in front of the plane, a plane
// reached only through material is refused, the proxy never passes through a thin wall:
// keep_proxy_outside); device faults, jumps and lost ticks; the filtered velocity
// (filter_velocity, hri_inline.h); the recovery ramp on every plane change (§3.3 after
// Mark et al., where the paper ramps an embedded update only: robust_ramp, ramp_force) and
// the release fade when contact ends with force on. How p and N are found: hri_plane.cpp.
// The common ticks written out for speed: hri_fast.cpp (the same bits as short_tick and
// tick_general here).

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>

#include "isotouch/servo/hri_inline.h"
#include "isotouch/servo/sampling.h"

namespace isotouch::servo {
namespace {

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
    // The ramp starts from the force sent, an edit ease's offset included: it takes the
    // ease over (both would add that offset).
    edit_easing_ = false;
    edit_ease_left_s_ = 0;
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

// The state in which quick_tick's ticks are tick_robust_full's: a configuration it covers
// (quick_ok_), started, no fault, restart, edit, ramp, release nor ease running. The quick
// ticks keep it; the paths that can change it (tick_general, tick_robust_full) set plain_
// from it when they end.
bool HriRenderer::plain_state() const {
  return quick_ok_ && started_ && !resync_ && vel_valid_ && lost_s_ == 0.0 && !after_fault_ && !edit_easing_ &&
         !(ramp_left_s_ > 0) && !(release_left_s_ > 0) && recovery_ticks_left_ <= 0 &&
         (version_known_ || !(params_.edit_period_s > 0));
}

// Out of line: the quick tick (quick_tick, hri_fast.cpp) then compiles as a small function.
[[gnu::noinline]] HriTick HriRenderer::tick_robust_full(const FieldView& field, const Vec3& hip, double dt_s) {
  HriTick t = tick_robust_full_body(field, hip, dt_s);
  if (show_eased_vhip_) t.vhip_m = eased_vhip_;  // the proxy on the receding surface (edit ease)
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
    edit_easing_ = false;  // zero force was sent: an edit ease ends here
    edit_ease_left_s_ = 0;
    release_left_s_ = 0;    // and a release fade
    prev_force_ = {};
    return result(out, plane_);
  }
  lost_s_ = 0;
  ramp_dt_s_ = std::min(dt, 2.0 * dt_nominal_s_);  // recovery ramp: this tick's period [s]
  if (!started_ || resync_) restart_at(hip);
  // Edits: a new snapshot version. Nothing read from the old snapshot
  // (the VHIP's cached value, the held plane's |grad|) is used on it.
  const bool edited = params_.edit_period_s > 0 && note_version(field.version()) && edit_reaches(field, hip);
  bool covered_free_vhip = false;  // a free VHIP outside in the old snapshot: a contact point now
  if (edited) {
    covered_free_vhip = !plane_.valid && ((vhip_value_known_ && !(excess(vhip_value_) > 0.0)) || vhip_outside_);
    vhip_value_known_ = false;
    vhip_outside_ = false;
    plane_grad_norm_ = 0;
    ramp_left_s_ = 0;  // the edit ease takes a running recovery ramp over
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

// Out of line: the common ticks (the short way: short_tick below, quick_tick in hri_fast.cpp)
// then compile as small functions.
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
    const bool fresh = !vhip_value_known_ || params_.edit_period_s > 0;
    if (reached_through_material(field, hip, held, held_grad_norm, voxel, fresh ? &f_vhip_now : nullptr)) {
      set_plane(held);
      plane_grad_norm_ = held_grad_norm;
    }
  }

  if (!holding || edited) {  // a new contact (or new material): its side
    entry_n_ = plane_.n;
    entry_hip_ = hip;
    entry_vhip_ = vhip_;
    entry_proxy_ = proxy_on_plane(hip);
    entry_deep_hip_ = hip;
    entry_deep_depth_ = 0.0;
    entry_held_ = false;
  }
  else if (out.plane_update) hold_entry_side(field, hip, have_f_hip && excess(f_hip) > 0.0, held, held_grad_norm, voxel, out);

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

bool HriRenderer::past_middle(const FieldView& field, const Vec3& hip, const Vec3& n, double depth,
                              double voxel) const {
  // Fifth-voxel steps both ways from the HIP, up to the depth plus a voxel: the material
  // ends both ways (a feature, whose entry side is still there: not a half-space), and along
  // -n no later than a quarter voxel after it does along n. The quarter voxel: at the middle
  // itself the two are as near, and a HIP just short of it on the trilinear field's blocky
  // section of a coarse feature would let the proxy turn there and the side follow it (a
  // rod two voxels of 3 mm thick wrapped at 0.8 of the limit).
  if (!(depth > 0.0)) return false;
  const double reach = depth + voxel;
  const int steps = chord_steps(reach, voxel);
  const int slack = int(std::ceil(0.25 * voxel / (reach / steps)));  // a quarter voxel, in steps
  FieldView::Segment far(field, hip, hip - n * reach), near(field, hip, hip + n * reach);
  int far_out = 0, near_out = 0;  // the steps where the material ends (0: not within reach)
  material_ends(far, near, steps, far_out, near_out);
  return far_out > 0 && near_out > 0 && far_out <= near_out + slack;
}

bool HriRenderer::face_along(const FieldView& field, const Vec3& hip, const Vec3& n, double reach, double voxel,
                             Vec3& q) const {
  const int steps = chord_steps(reach, voxel);
  FieldView::Segment seg(field, hip, hip + n * reach);
  int out_i = 0;
  for (int i = 1; i <= steps && out_i == 0; ++i)
    if (!(excess(seg.value(double(i) / steps)) > 0.0)) out_i = i;
  if (out_i == 0) return false;
  double lo = double(out_i - 1) / steps, hi = double(out_i) / steps;  // lo inside, hi outside
  for (int k = 0; k < 20; ++k) {
    const double mid = 0.5 * (lo + hi);
    (excess(seg.value(mid)) > 0.0 ? lo : hi) = mid;
  }
  q = hip + n * (reach * hi);
  return finite(q);
}

int HriRenderer::chord_steps(double reach, double voxel) const {
  return int(std::clamp(std::ceil(reach / (0.2 * voxel)), 2.0, double(std::max(2, params_.march_budget / 2))));
}

void HriRenderer::material_ends(FieldView::Segment& a, FieldView::Segment& b, int steps, int& a_out,
                                int& b_out) const {
  for (int i = 1; i <= steps && (a_out == 0 || b_out == 0); ++i) {
    const double t = double(i) / steps;
    if (a_out == 0 && !(excess(a.value(t)) > 0.0)) a_out = i;
    if (b_out == 0 && !(excess(b.value(t)) > 0.0)) b_out = i;
  }
}

void HriRenderer::hold_entry_side(const FieldView& field, const Vec3& hip, bool hip_inside, const VirtualPlane& held,
                                  double held_grad_norm, double voxel, TickOut& out) {
  static const double kCos = std::cos(kEntryConeDeg * M_PI / 180.0);
  if (!hip_inside) {  // the HIP left the material: the side is free again
    entry_held_ = false;
    entry_deep_depth_ = 0.0;
  }
  // Once held, every update keeps the held plane while the HIP stays inside: a plane within
  // the cone of entry_n_ is still up to 20 deg from it, and the proxy sliding on one turned
  // toward the far side crossed the middle (on a noisy crest each update turned it that way).
  const double depth = held.valid ? dot(held.n, held.p - hip) : 0.0;  // the HIP behind the held plane [m]
  // The deepest HIP along entry_n_ since it was set (no read): a turn that comes after the
  // HIP went past the middle and then moved on (stroked across a cylinder's crest it is
  // nearer the near face along entry_n_ again) is checked from there too, below.
  if (hip_inside && depth > 0.0 && dot(entry_n_, entry_deep_hip_ - hip) > 0.0) {
    entry_deep_hip_ = hip;
    entry_deep_depth_ = depth;
  }
  if (!plane_.valid || !hip_inside) return;
  // A turn the hand did not make (pressed_round below: the proxy went a quarter voxel
  // farther across entry_n_ than the HIP) is checked within the cone too, where its
  // no-read part holds: on a 2-voxel cylinder on 1 x 1 x 3 mm voxels the contact's normal
  // came 25 deg off the crest's, and with the HIP pressed straight down past the axis the
  // iteration carried the proxy round in steps that stayed inside the cone of that normal
  // until it was 42 deg off the crest's, then held that plane and the across stroke slid
  // the proxy down it past the axis at 0.6 of the limit (HriRidges seed 13; 23, 28 and 29
  // wrapped at 0.4-0.7 so too).
  auto across = [&](const Vec3& d) { return norm(d - entry_n_ * dot(entry_n_, d)); };
  const Vec3 hip_moved = hip - entry_hip_;
  const bool in_cone = !entry_held_ && dot(plane_.n, entry_n_) >= kCos;
  // Inside the cone, from the proxy the entry plane gave (entry_proxy_): the VHIP when
  // entry_n_ was set was the proxy on the plane before, and its step onto the new one (on the
  // engine block's metal, 1.5 mm across a face whose normal followed a 90-deg turn) counted
  // as a carry; the hold then kept that face's plane through the lift, pulling inward.
  const Vec3 proxy_then = in_cone ? entry_proxy_ : entry_vhip_;
  const bool carried = dot(hip_moved, hip_moved) > 0.0625 * voxel * voxel &&
                       across(vhip_ - proxy_then) > across(hip_moved) + 0.25 * voxel && depth > 0.0;
  if (in_cone && !carried) return;
  // The plane turned beyond the cone: over a thin feature's edge with the HIP past its
  // middle (the wrap-around), or sliding over a curved surface (the side follows). Once
  // past the middle the side is held until the HIP leaves the material: near the middle
  // the test can go either way from one update to the next, and a side that followed one
  // turn let the next one go on round.
  // Along the new plane's normal too: a HIP at or past the middle of the chord that way is
  // no nearer the new face than the opposite one, and the turn is the plane iteration
  // carrying the proxy round the feature (each update projects the pressed HIP onto a plane
  // tilted a little more), not a slide over a curved surface. Checked along entry_n_ alone,
  // the turns made before the HIP reached the middle along it moved entry_n_ with them: at
  // n = 1 the iteration runs ten times as often as at n = 10 and a 2-voxel cylinder wrapped
  // at 0.6 of the limit at n = 1, none at n = 10.
  const double new_depth = dot(plane_.n, plane_.p - hip);
  // A turn the hand did not make: since entry_n_ was set the HIP moved (a quarter voxel) and
  // the proxy went farther across entry_n_ than the HIP did, by more than a quarter voxel.
  // Sliding over a surface (curved or pressed obliquely) carries the proxy as far across as
  // the HIP; here the plane iteration carries it on round a rounded crest (each update
  // projects the HIP onto a plane already tilted toward the crest, which tilts the next one
  // more; entry_n_ followed in 20-deg steps and a 4-voxel ridge wrapped at n = 1-2). A
  // surface that changes under a still HIP is followed.
  // Only on a thin feature: its far face within the HIP's depth and two voxels (the smallest
  // spacing) along -entry_n_. Sliding pressed over convex bulk material carries the proxy
  // farther across than the HIP too, by R / (R - depth): on the sphere of scenes/sphere.json
  // (1.1 mm deep on a 20 mm radius) 7.18 against 6.84 mm by a 20 deg turn; held there, the
  // plane kept the 20 deg normal round the sphere's side and turned 60 deg at the lift. On the
  // chest CT's bone wall (1.68 x 1.68 x 5 mm voxels; far face 9.2 mm behind a HIP 1.46 mm
  // deep) a hold kept the plane while the lift went out along the far side's normal, 3.3 N
  // until the HIP left the bone; with the voxel's width along entry_n_ (5 mm there) the wall
  // counted as thin. There is no far side there to wrap round to.
  // Or thin for this servo: the middle within the depth the force limit presses to (a wall
  // up to twice that thick: limit / K, world [m]), which a hand pressing below the limit
  // reaches. Two of the smallest voxels missed ridges of 2-3 voxels on 1 x 1 x 3 mm voxels
  // (5.4-8 mm thick along the press; pressed on the crest's rounded corner the plane turned
  // with the proxy onto the crest in sub-20-deg steps and the across stroke wrapped at 0.7
  // of the limit: HriRidges seeds 5, 6, 11, 12). The chest's bone wall (10.7 mm, its middle
  // 5.3 mm in) and the sphere lie beyond it.
  const double k = params_.stiffness_n_per_m;
  const double thin_wall = k > 0.0 ? 2.0 * params_.force_limit_n / k * params_.world_per_device : 0.0;
  Vec3 far_face;
  const double far_reach = std::max(depth + 2.0 * voxel, thin_wall - depth);  // a far face within: thin
  const bool pressed_round = carried && face_along(field, hip, entry_n_ * -1.0, far_reach, voxel, far_face);
  if (in_cone && !pressed_round) return;  // within the cone only that turn is held
  // Past the middle at the deepest HIP since entry_n_ was set: the HIP pressed past a
  // cylinder's axis along a normal 25 deg off the crest's and then stroked across it was
  // no longer past the middle along entry_n_ when the turn came, and the proxy slid round
  // to the far side at 0.4 of the limit (HriRidges seed 13; 17 at 0.5).
  auto deep_past = [&]() {
    const Vec3 d = entry_deep_hip_ - hip;
    return entry_deep_depth_ > 0.0 && dot(d, d) > 0.0 &&
           past_middle(field, entry_deep_hip_, entry_n_, entry_deep_depth_, voxel);
  };
  if (depth > 0.0 && (entry_held_ || pressed_round || past_middle(field, hip, entry_n_, depth, voxel) ||
                      past_middle(field, hip, plane_.n, new_depth, voxel) || deep_past())) {
    VirtualPlane kept = held;
    // A turn the iteration made is undone: the plane faces entry_n_ again (the HIP behind it).
    if (!entry_held_ && dot(entry_n_, hip - held.p) < 0.0) kept.n = entry_n_;
    entry_held_ = true;
    // The material under the face found from the HIP is about as thick along the held normal
    // (within half a voxel) as under the point where the side was taken: a wall whose surface
    // falls away under the stroke and goes on lower (never lowered, the head CT's held plane
    // stayed 2.8 mm above it and the hold ended with 2.4 N released in one tick), not the
    // thinning corner round a crest (lowered there, ridges wrapped at 0.5-0.9 of the limit).
    auto as_thick_as_entry = [&](const Vec3& at) {
      const double reach = 12.0 * voxel, in = 0.5 * voxel;
      Vec3 a, b;
      if (!face_along(field, at - kept.n * in, kept.n * -1.0, reach, voxel, a)) return true;
      if (!face_along(field, entry_vhip_ - kept.n * in, kept.n * -1.0, reach, voxel, b)) return false;
      return norm(a - at) >= norm(b - entry_vhip_) - 0.5 * voxel;
    };
    // The held plane's point goes to the face found from the HIP along its normal: up always
    // (a tilted held plane slid the proxy down it on a stroke along the feature), down only
    // with the HIP short of the middle along that normal and the wall as thick there.
    // The reach: the HIP's depth along the normal kept (entry_n_ where the turn was undone;
    // along held.n, 20-45 deg off it, a held point lying to the side gave a longer reach and
    // the proxy went up past depth + voxel in one update: HriEntrySide).
    const double kept_depth = dot(kept.n, kept.p - hip);
    Vec3 q;
    if (face_along(field, hip, kept.n, kept_depth + voxel, voxel, q) &&
        (dot(kept.n, q - kept.p) > 0.0 ||
         (!past_middle(field, hip, kept.n, kept_depth, voxel) && as_thick_as_entry(q))))
      kept.p = q;
    adopt_plane(kept, hip, out);
    plane_grad_norm_ = held_grad_norm;
  } else {
    entry_n_ = plane_.n;
    entry_hip_ = hip;
    entry_vhip_ = vhip_;
    entry_proxy_ = proxy_on_plane(hip);
    entry_deep_hip_ = hip;
    entry_deep_depth_ = 0.0;
  }
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
  // from the force sent); an edit ease takes it over. The proxy is on no
  // surface while it fades: contact = false.
  if (in_contact || out.fault || edit_easing_ || edited || !(params_.recovery_time_s > 0)) {
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
    out.penetration_m = 0;
    ++release_fade_ticks_;
  }
  show_eased_vhip_ = false;
  if (edited && !out.fault) {
    edit_easing_ = true;
    edit_ease_left_s_ = params_.edit_period_s;
    edit_ease_from_ = prev_force_ - force;
    edit_ease_max_rate_ = std::max(edit_ease_max_rate_, norm(edit_ease_from_) / params_.edit_period_s);
  }
  if (edit_easing_) {
    if (out.fault) edit_easing_ = false;
    else mag = edit_ease(hip, force, mag, out);
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
