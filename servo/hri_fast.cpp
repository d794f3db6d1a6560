// hri_fast.cpp - tick(), and the robust variant's two common ticks written out: contact
// behind a held plane with no update due (Figure 2's `c = c + 1` branch, then eqs. 2 and 3)
// and free motion outside on a short step (no read while the HIP stays in a cell whose
// corners are all outside). The robust tick's arithmetic for the plain state, each point
// computed once, inlined into tick() so that its values stay in registers; every other tick
// leaves by a call in tail position (quick_contact_limited and free_read_tick here;
// tick_robust_full and, through general_tick, tick_general in hri_robust.cpp). The same bits
// as the general path (the HriShortWay tests).

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>

#include "isotouch/servo/hri_inline.h"
#include "isotouch/servo/sampling.h"

namespace isotouch::servo {

// The robust tick from the plain state. Every way out that is not a common tick is a call in
// tail position (tick_robust_full, general_tick, the free tick's read, the force limit), so
// the common ticks keep their values in registers the calls may clobber: tick() saves one
// register where it saved six, and builds the HriTick from registers.
[[gnu::always_inline]] inline HriTick HriRenderer::quick_tick(const FieldView& field, const Vec3& hip, double dt_s) {
  // The plain state: the robust tick's fault, restart, edit, ramp, release and ease branches
  // cannot act (each of those ticks takes the full path). In it after_fault_ is false,
  // lost_s_ is 0, none of ramp_left_s_, release_left_s_ and recovery_ticks_left_ is above 0
  // (every reader tests that), version_known_ is true where edits are tracked, and sliding_
  // is false (no friction): the full path's stores of them would change nothing.
  if (!plain_) return tick_robust_full(field, hip, dt_s);
  if (params_.edit_period_s > 0 && field.version() != field_version_) return tick_robust_full(field, hip, dt_s);
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
  if (!in_cell && params_.edit_period_s > 0) {
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

}  // namespace isotouch::servo
