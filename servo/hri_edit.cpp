// hri_edit.cpp - edits, not in the paper (its volumes do not change while touched): a tick
// that reads another snapshot version is an edit tick when the changed box reaches what the
// renderer read (note_version, edit_reaches); the plane is then re-evaluated at once, the
// force step the edit causes is eased out over the time its material took to remove
// (edit_ease: edit_period_s, the force follows the material removed), and material added
// deeper than the embedded-VHIP search reaches is marched out of (march_out). hri.h, "Edits".

#include "isotouch/servo/hri.h"

#include <algorithm>
#include <cmath>

#include "isotouch/servo/sampling.h"

namespace isotouch::servo {

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

double HriRenderer::edit_ease(const Vec3& hip, Vec3& force, double mag, TickOut& out) {
  // What the edit removed (or added) was cut over edit_period_s, not in the tick it was
  // published: the offset between the force sent before it and the new target fades out
  // linearly over that time, added to the target (so the user's own motion passes at once).
  edit_ease_left_s_ -= ramp_dt_s_;
  if (!(edit_ease_left_s_ > 1e-9 * params_.edit_period_s)) {  // done (or a NaN period)
    edit_ease_left_s_ = 0;
    edit_easing_ = false;
    return mag;
  }
  const Vec3 offset = edit_ease_from_ * (edit_ease_left_s_ / params_.edit_period_s);
  const Vec3 target = force;
  force = target + offset;
  double sent = norm(force);
  // Between two forces within the limit the blend is within it; the target may have grown
  // since the edit tick (the user pressing on): saturate again.
  if (sent > params_.force_limit_n) {
    out.saturated = saturate(force, params_.force_limit_n);
    sent = norm(force);
  }
  ++edit_eased_ticks_;
  if (sent > 0.0) {
    // The proxy the force stands for, on the surface as the material recedes: F = K (proxy -
    // HIP) / world_per_device, so the offset moves it by E s * world_per_device / K.
    const double k = params_.stiffness_n_per_m;
    eased_vhip_ = vhip_ + (force - target) * (params_.world_per_device / k);
    show_eased_vhip_ = k > 0.0;
    out.contact = true;
    out.penetration_m = norm(eased_vhip_ - hip);
  }
  return sent;
}

}  // namespace isotouch::servo
