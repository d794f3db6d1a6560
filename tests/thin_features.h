// thin_features.h - test helper: thin features (fins and tapering cylinders 1-4 voxels
// thick, on 1 mm and 1 x 1 x 3 mm voxels) pressed and stroked by the HRI servo, and whether
// the proxy wraps round to the far side below the force limit. Shared by
// tests/test_hri_contact.cpp (the point probe) and tests/test_hri_tool.cpp (the spherical
// tool). Truth from the analytic shapes: the feature's middle and entry normal.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/servo/hri.h"
#include "field_builders.h"

namespace isotouch::test {

using core::SampleField;
using core::Vec3;

/// A field of `dims` voxels with spacing `sp` [m] from an analytic value [mm] and gradient
/// [mm/m] (positive inside, InsideIs::kAbove, tau = 0).
inline SampleField make_spaced_field(std::array<int, 3> dims, Vec3 sp, const std::function<double(const Vec3&)>& value,
                                     const std::function<Vec3(const Vec3&)>& grad) {
  return sample_analytic(dims, sp, {0, 0, 0}, value, grad);
}

/// One thin feature: its field, the outward normal of the face pressed (n_entry), a point of
/// its mid-plane (a fin) or axis (a cylinder) `mid`, and where and along what it is stroked.
struct ThinFeature {
  SampleField field;
  Vec3 mid;            ///< on the fin's mid-plane / the cylinder's axis, under the press point [m]
  Vec3 n_entry;        ///< outward normal of the side pressed (unit)
  double half = 0;     ///< half the thickness (fin) / the radius (cylinder) under the press point [m]
  Vec3 along, across;  ///< stroke directions (unit, perpendicular to n_entry)
  double along_len = 0, across_len = 0;  ///< stroke lengths for a point [m] (stroke_len: a tool's)
  /// The along stroke ends at the feature's end (a tapering cylinder's tip, along_len from
  /// the press point): a tool's stops where its sphere reaches that end, along_len less r.
  bool along_to_end = false;
  /// A scan-like feature (noise, partial-volume edges: thin_ridges.h): the normal of its
  /// crest wobbles a few degrees, so a point probe's force beside the crest counts as turned
  /// against the entry normal only beyond 0.1 of |F| (a tool's slack), not at any sign.
  bool scan_like = false;
};

/// The length of stroke `s` (0 along, 1 across) of `tf` for a tool of radius r [m] (0: a
/// point). Across, and along a fin's edge, the tool goes r farther than the point (its
/// sphere clears the edge by what the point does). Along a tapering cylinder the stroke ends
/// when the tool's sphere reaches the tip: past the tip's end no material lies between the
/// tool's centre and a HIP pressed below the axis, and a rigid burr (a god-object: the
/// nearest free place to the HIP, reached by sliding) rolls round the end cap onto the HIP,
/// its distance to the HIP falling all the way; a hold there would keep a burr stuck to a
/// spike's point. HriTool.ABurrStrokedPastASpikesTipRollsOffItsEnd tests that roll-off.
inline double stroke_len(const ThinFeature& tf, int s, double r) {
  if (s == 0) return tf.along_to_end ? tf.along_len - r : tf.along_len + r;
  return tf.across_len + r;
}

/// A fin-like feature's press and strokes: the plate of width w along m with its edge along
/// cross(m, t), c - t edge_in its press point's middle; stroked 16 mm along, edge_in + 4 mm across.
inline void plate_frame(ThinFeature& tf, Vec3 c, Vec3 m, Vec3 t, double w, double edge_in) {
  tf.mid = c - t * edge_in;
  tf.n_entry = m;
  tf.half = 0.5 * w;
  tf.along = cross(m, t);
  tf.across = t;
  tf.along_len = 0.016;
  tf.across_len = edge_in + 0.004;
}

/// A fin: the plate |m.(x - c)| < w/2 on the side t.(x - c) < 0 of its straight free edge
/// (t perpendicular to m), pressed on its face 1.5 voxels in from the edge; stroked along
/// the edge and across it (toward the edge and past it).
inline ThinFeature fin(Vec3 m, Vec3 t, double w, Vec3 sp) {
  const Vec3 c{0.024, 0.024, 0.036};
  const std::array<int, 3> dims{int(0.048 / sp.x) + 1, int(0.048 / sp.y) + 1, int(0.072 / sp.z) + 1};
  const double edge_in = 1.5 * std::abs(dot(t, sp));  // the press point's distance from the edge [m]
  ThinFeature tf;
  tf.field = make_spaced_field(
      dims, sp, [=](const Vec3& x) { return 1000.0 * std::min(0.5 * w - std::abs(dot(m, x - c)), -dot(t, x - c)); },
      [=](const Vec3& x) {
        const double a = 0.5 * w - std::abs(dot(m, x - c)), b = -dot(t, x - c);
        return a < b ? m * (dot(m, x - c) >= 0 ? -1000.0 : 1000.0) : t * -1000.0;
      });
  plate_frame(tf, c, m, t, w, edge_in);
  return tf;
}

/// A tapering cylinder along unit a: radius R(s) = R0 (-s / L) for s = a.(x - c) in [-L, 0]
/// (the tip at c), R0 beyond; pressed from n (perpendicular to a) where the diameter is
/// `diam`, stroked along the axis up to the tip (stroke_len) and across it.
inline ThinFeature taper(Vec3 a, Vec3 n, double r0, double diam, Vec3 sp) {
  const Vec3 c{0.024, 0.024, 0.036};
  const double len = 0.024;  // taper length [m]
  const std::array<int, 3> dims{int(0.048 / sp.x) + 1, int(0.048 / sp.y) + 1, int(0.072 / sp.z) + 1};
  auto radius = [=](double s) { return r0 * std::clamp(-s / len, 0.0, 1.0); };
  ThinFeature tf;
  tf.field = make_spaced_field(
      dims, sp,
      [=](const Vec3& x) {
        const double s = dot(a, x - c);
        return 1000.0 * (radius(s) - norm((x - c) - a * s));
      },
      [=](const Vec3& x) {
        const double s = dot(a, x - c);
        const Vec3 rv = (x - c) - a * s;
        const double rl = norm(rv);
        const double dr = (s > -len && s < 0) ? -r0 / len : 0.0;
        return (rl > 0 ? rv / rl * -1000.0 : Vec3{}) + a * (1000.0 * dr);
      });
  const double s0 = -len * (0.5 * diam / r0);  // where the radius is diam / 2
  tf.mid = c + a * s0;
  tf.n_entry = n;
  tf.half = 0.5 * diam;
  tf.along = a;
  tf.across = cross(n, a);
  tf.along_len = -s0;  // to the tip
  tf.along_to_end = true;
  tf.across_len = 0.5 * diam + 0.004;
  return tf;
}

struct ThinCase {
  const char* name;
  int voxels;  ///< thickness in voxels along the press direction
  ThinFeature feature;
};

/// The fins and tapering cylinders 1-4 voxels thick, on 1 mm voxels and on 1 x 1 x 3 mm
/// voxels (pressed across the fine axes and across the coarse one).
inline std::vector<ThinCase> thin_cases() {
  std::vector<ThinCase> cases;
  const Vec3 iso{1e-3, 1e-3, 1e-3}, aniso{1e-3, 1e-3, 3e-3};
  const Vec3 X{1, 0, 0}, Y{0, 1, 0}, Z{0, 0, 1};
  auto unit = [](Vec3 v) { return v / norm(v); };
  for (int k = 1; k <= 4; ++k) {
    cases.push_back({"fin, 1 mm voxels", k, fin(unit(Vec3{1, 0.2, 0.1}), unit(Vec3{-0.2, 1, 0}), k * 1e-3, iso)});
    cases.push_back({"fin across x, 1x1x3 mm", k, fin(X, Z, k * 1e-3, aniso)});
    cases.push_back({"fin across z, 1x1x3 mm", k, fin(Z, X, k * 3e-3, aniso)});
    cases.push_back({"tapering cylinder, 1 mm voxels", k, taper(unit(Vec3{0.1, 1, 0.2}), unit(Vec3{1, -0.1, 0}), 3e-3, k * 1e-3, iso)});
    cases.push_back({"tapering cylinder along z, 1x1x3 mm", k, taper(Z, X, 3e-3, k * 1e-3, aniso)});
    cases.push_back({"tapering cylinder along x, 1x1x3 mm", k, taper(X, Z, 9e-3, k * 3e-3, aniso)});
  }
  return cases;
}

/// Whether the probe at a HIP [m] is inside the material (the point: the HIP's trilinear
/// value; the tool: its sphere overlaps the material).
using InsideTest = std::function<bool(const Vec3& hip)>;

/// One press-and-stroke at `level` of the force limit (the HIP pressed level * limit / K past
/// where the probe touches the entry surface: the surface for a point, the tool's radius
/// above it for the tool, then stroked `dir` * len at 40 mm/s): true if the proxy (the
/// tool's centre) crossed to the far side of the feature's middle (by 0.1 voxel; or the
/// force turned against the entry normal) on a tick whose HIP has stayed inside (`inside`)
/// since contact began. The sent force at that tick in `wrap_force`.
inline bool wraps(const ThinFeature& tf, const servo::HriParams& p, double level, const Vec3& dir, double len,
                  const InsideTest& inside, double& wrap_force, bool debug) {
  servo::HriRenderer r(p);
  const Vec3 top = tf.mid + tf.n_entry * (tf.half + p.tool_radius_m);
  const double depth = level * p.force_limit_n / p.stiffness_n_per_m;
  const Vec3 start = top + tf.n_entry * 0.003;
  bool touched = false, inside_since = true;
  for (int k = 0; k < 2000; ++k) {
    const double t = k * 1e-3;
    const double down = std::min(0.02 * t, 0.003 + depth);  // 20 mm/s in
    const double tau_stroke = 0.003 / 0.02 + (0.003 + depth) / 0.02 + 0.1;
    const double along = std::clamp(0.04 * (t - tau_stroke), 0.0, len);
    const Vec3 hip = start - tf.n_entry * down + dir * along;
    const servo::HriTick out = r.tick(tf.field, hip);
    if (!touched && out.contact && inside(hip)) touched = true;  // contact began, the HIP inside
    if (!touched) continue;
    inside_since = inside_since && inside(hip);
    if (!inside_since) break;
    const double side = dot(out.vhip_m - tf.mid - dir * dot(out.vhip_m - tf.mid, dir), tf.n_entry);
    if (debug && std::getenv("HRI_THIN_TICKS"))
      std::printf("      k %d c %d u %d plane n.d %.3f n.n %.3f valid %d side %.3f hip side %.3f |F| %.3f\n", k, int(out.contact),
                  int(out.plane_update), dot(out.plane.n, dir), dot(out.plane.n, tf.n_entry), int(out.plane.valid), side * 1e3,
                  1e3 * dot(hip - tf.mid, tf.n_entry), norm(out.force_n));
    // Past the middle by more than a tenth of a voxel (at the middle itself, with the HIP
    // there, either side is as near), or a force toward the far side: for a tool, more than
    // 0.1 of |F| toward it (a tool beside a fin's edge face, level with the HIP, pushes
    // sideways, a few degrees either way on the trilinear face; so does a point beside a
    // scan-like crest).
    const Vec3& sp = tf.field.grid.spacing_m;
    const double toward_far = p.tool_radius_m > 0.0 || tf.scan_like ? -0.1 * norm(out.force_n) : 0.0;
    const bool far = side < -0.1 * std::min({sp.x, sp.y, sp.z}) || dot(out.force_n, tf.n_entry) < toward_far;
    if (far && norm(out.force_n) < 0.999 * p.force_limit_n) {
      if (debug)
        std::printf("    wrap at k %d: vhip side %.3f mm, |F| %.3f N, F.n %.3f N, hip depth %.3f mm\n", k, side * 1e3,
                    norm(out.force_n), dot(out.force_n, tf.n_entry), 1e3 * dot(top - hip, tf.n_entry));
      wrap_force = norm(out.force_n);
      return true;
    }
  }
  return false;
}

/// The lowest press (0.1, 0.2, ... 1.0 of the limit) that wraps in any stroke of `tc` (along
/// and across the feature, plane update periods `periods`, the rest of `base`); 2 if none
/// does. `runs` counts the strokes. HRI_THIN_DEBUG=1 lists the wrap ticks, HRI_THIN_TICKS=1
/// too every tick before them.
inline double lowest_wrapping_press(const ThinCase& tc, const servo::HriParams& base, const InsideTest& inside,
                                    long& runs, const std::vector<int>& periods = {1, 10}) {
  const bool debug = std::getenv("HRI_THIN_DEBUG") != nullptr;
  double lowest = 2;
  for (const int n : periods) {
    servo::HriParams p = base;
    p.plane_update_period = n;
    for (int s = 0; s < 2; ++s) {
      const Vec3 dir = s == 0 ? tc.feature.along : tc.feature.across;
      const double len = stroke_len(tc.feature, s, p.tool_radius_m);
      for (int l = 1; l <= 10; ++l) {
        double f = 0;
        ++runs;
        if (wraps(tc.feature, p, 0.1 * l, dir, len, inside, f, false)) {
          if (debug) {
            std::printf("  %s, %d voxels, r %.1f mm, n %d, %s, level %.1f:\n", tc.name, tc.voxels,
                        p.tool_radius_m * 1e3, n, s ? "across" : "along", 0.1 * l);
            wraps(tc.feature, p, 0.1 * l, dir, len, inside, f, true);
          }
          lowest = std::min(lowest, 0.1 * l);
          break;
        }
      }
    }
  }
  return lowest;
}

/// "none up to 1.0 of the limit" or "0.4 of the limit" for a lowest_wrapping_press.
inline std::string press_text(double lowest) {
  return lowest > 1.5 ? "none up to 1.0 of the limit" : (std::to_string(lowest).substr(0, 3) + " of the limit");
}

}  // namespace isotouch::test
