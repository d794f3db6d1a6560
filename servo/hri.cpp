// hri.cpp - HriRenderer's frame, common to both variants: the constructor (the paper
// variant's fixed choice of p and N, the configuration the quick tick covers), reset, the
// restart to free motion, and the plane a tick reports.
//
// The renderer (hri.h documents the class and every departure from the paper) is split by
// the part of the paper each file implements or departs from:
//   hri_paper.cpp   Figure 2 exactly as printed (Variant::kPaper); §3.1's friction
//   hri_inline.h    eqs. 2 and 3 (the contact force, both variants) and the few small pieces
//                   that the ticks of several of these files inline
//   hri_plane.cpp   eq. 1's plane: p on the segment VHIP -> HIP, N = SurfaceNormal(p), and
//                   beside them the robust ways of finding p (embedded VHIP, thin walls)
//   hri_robust.cpp  the robust tick (Variant::kRobust): the rest of the departures
//   hri_edit.cpp    edits (not in the paper): a new snapshot version, the edit ease
//   hri_tool.cpp    the spherical tool (not in the paper): several planes at once
//   hri_fast.cpp    tick(), and the robust common ticks written out for speed (same bits)

#include "isotouch/servo/hri.h"

#include <cmath>

namespace isotouch::servo {

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
  quick_ok_ = quick_covered();
}

bool HriRenderer::quick_covered() const {
  return params_.variant == Variant::kRobust && params_.short_way && !(params_.tool_radius_m > 0.0) &&
         !params_.force_shading && !params_.friction.any() && std::isfinite(params_.max_reach_m * params_.max_reach_m);
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
  edit_easing_ = false;
  edit_ease_left_s_ = 0;
  show_eased_vhip_ = false;
  prev_force_ = {};
  tool_plane_count_ = 0;
  scan_valid_ = false;
  release_left_s_ = 0;
  prev_target_f_ = {};
  ramp_from_dir_ = {};
  entry_n_ = {};
  entry_held_ = false;
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

VirtualPlane HriRenderer::reported_plane() const {
  if (!(params_.tool_radius_m > 0.0)) return plane_;
  if (tool_plane_count_ == 0) return {};
  return {tool_planes_[0].n, tool_planes_[0].p, true};
}

}  // namespace isotouch::servo
