// hri_edit.cpp - edits, not in the paper (its volumes do not change while touched): a tick
// that reads another snapshot version is an edit tick when the changed box reaches what the
// renderer read (note_version, edit_reaches); the plane is then re-evaluated at once and
// the force vector slewed from the one sent toward the new target (edit_slew:
// edit_max_step_fraction of the limit and edit_max_turn_deg per tick), and material added
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

}  // namespace isotouch::servo
