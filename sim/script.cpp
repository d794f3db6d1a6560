#include "isotouch/sim/script.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "isotouch/servo/sampling.h"

namespace isotouch::sim {

void TouchScript::at(double t, Vec3& pos, Vec3& vel) const {
  vel = {};
  if (waypoints.empty()) {
    pos = {};
    return;
  }
  if (t <= waypoints.front().t_s) {
    pos = waypoints.front().pos_m;
    return;
  }
  if (t >= waypoints.back().t_s) {
    pos = waypoints.back().pos_m;
    return;
  }
  auto it = std::upper_bound(waypoints.begin(), waypoints.end(), t,
                             [](double v, const Waypoint& w) { return v < w.t_s; });
  const Waypoint& b = *it;
  const Waypoint& a = *(it - 1);
  const double dt = b.t_s - a.t_s;
  const double u = dt > 0 ? (t - a.t_s) / dt : 1.0;
  pos = a.pos_m + (b.pos_m - a.pos_m) * u;
  vel = dt > 0 ? (b.pos_m - a.pos_m) / dt : Vec3{};
}

void TouchScript::retrace_lift(const std::vector<Vec3>& tool_path) {
  // The waypoint the lift starts from, and the lift's end (the next waypoint).
  std::size_t i = 0;
  while (i + 1 < waypoints.size() && waypoints[i + 1].t_s <= t_lift) ++i;
  if (tool_path.empty() || i + 1 >= waypoints.size()) return;
  const Waypoint from = waypoints[i], up = waypoints[i + 1];
  std::vector<Vec3> pts{from.pos_m};
  pts.insert(pts.end(), tool_path.rbegin(), tool_path.rend());
  pts.push_back(up.pos_m);
  double length = 0;
  for (std::size_t k = 1; k < pts.size(); ++k) length += norm(pts[k] - pts[k - 1]);
  std::vector<Waypoint> out(waypoints.begin(), waypoints.begin() + std::ptrdiff_t(i) + 1);
  double s = 0;
  for (std::size_t k = 1; k + 1 < pts.size(); ++k) {
    s += norm(pts[k] - pts[k - 1]);
    out.push_back({from.t_s + (up.t_s - from.t_s) * (length > 0 ? s / length : 1.0), pts[k]});
  }
  out.insert(out.end(), waypoints.begin() + std::ptrdiff_t(i) + 1, waypoints.end());
  waypoints = std::move(out);
}

namespace {

// Most stroke points; ds grows for long strokes on fine grids. Each point marches at most
// kStrokeMarchSteps samples, so a stroke costs at most ~1e7 samples whatever the grid.
constexpr long kMaxStrokeSteps = 10000;
constexpr long kStrokeMarchSteps = 1024;

// Slab test: the part [t0, t1] of origin + dir * t that lies in the grid's box.
bool clip_to_box(const Grid& g, const Vec3& o, const Vec3& d, double& t0, double& t1) {
  const Vec3 lo = g.origin_m, hi = g.origin_m + g.extent_m();
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return std::isfinite(t0) && std::isfinite(t1) && t0 <= t1;
}

std::string mm(const Vec3& v) {
  std::ostringstream s;
  s.precision(4);
  s << "(" << v.x * 1e3 << ", " << v.y * 1e3 << ", " << v.z * 1e3 << ") mm";
  return s.str();
}

}  // namespace

bool find_surface(const SampleField& field, const HriRenderer& r, const Vec3& origin,
                  const Vec3& dir, double max_dist, Vec3& hit, long max_steps) {
  const Vec3& sp = field.grid.spacing_m;
  if (r.excess(sample_value(field, origin)) > 0.0) return false;
  // Only the part of the ray inside the volume box can cross the isosurface (outside it
  // the field is NaN, never inside).
  double t0 = 0.0, t1 = max_dist;
  if (!(max_dist > 0.0) || !clip_to_box(field.grid, origin, dir, t0, t1)) return false;
  // The step grows where the ray inside the box is longer than max_steps steps.
  const double step = std::max(0.25 * std::min({sp.x, sp.y, sp.z}), (t1 - t0) / double(std::max(1L, max_steps)));
  double t_out = t0;
  const long n = long(std::ceil((t1 - t0) / step)) + 1;
  for (long i = 1; i <= n; ++i) {
    const double t = std::min(t0 + double(i) * step, t1);
    if (r.excess(sample_value(field, origin + dir * t)) > 0.0) {
      double lo = t_out, hi = t;
      for (int k = 0; k < 50; ++k) {
        const double mid = 0.5 * (lo + hi);
        (r.excess(sample_value(field, origin + dir * mid)) > 0.0 ? hi : lo) = mid;
      }
      hit = origin + dir * (0.5 * (lo + hi));
      return true;
    }
    t_out = t;
  }
  return false;
}

TouchScript make_touch_script(const SampleField& field, const HriParams& hri,
                              const ScriptParams& p) {
  const Grid& g = field.grid;
  const HriRenderer classify(hri);
  const Vec3 lo = g.origin_m, ext = g.extent_m();
  for (int a = 0; a < 3; ++a)
    if (!(p.ray_origin_frac[a] >= kRayOriginFracMin && p.ray_origin_frac[a] <= kRayOriginFracMax)) {
      std::ostringstream e;
      e << "script.ray_origin_frac: each must be in [" << kRayOriginFracMin << ", " << kRayOriginFracMax
        << "] (fractions of the volume box), got " << p.ray_origin_frac[a] << " along axis " << a;
      throw std::runtime_error(e.str());
    }
  const Vec3 origin{lo.x + p.ray_origin_frac.x * ext.x, lo.y + p.ray_origin_frac.y * ext.y,
                    lo.z + p.ray_origin_frac.z * ext.z};
  const Vec3 dir = normalized_or(p.ray_direction, {});
  auto describe = [&] {
    std::ostringstream s;
    s.precision(4);
    s << "script: the ray from " << mm(origin) << " along (" << dir.x << ", " << dir.y << ", " << dir.z
      << ") (volume box " << mm(lo) << " to " << mm(lo + ext) << ")";
    return s.str();
  };
  if (norm(dir) == 0.0) throw std::runtime_error("script.ray_direction must not be zero");
  if (classify.excess(sample_value(field, origin)) > 0.0)
    throw std::runtime_error(describe() + " starts inside the isosurface; move ray_origin_frac");
  const double diag = norm(ext) * 2.0 + norm(origin - g.centre_m()) * 2.0;
  TouchScript s;
  if (!find_surface(field, classify, origin, dir, diag, s.contact_point_m))
    throw std::runtime_error(describe() + " never crosses the isovalue " +
                             std::to_string(hri.tau));
  const FieldValue fv = sample_trilinear(field, s.contact_point_m);
  const Vec3 g_out = Isosurface{hri.tau, hri.inside}.outward(fv.gradient);
  const Vec3 n = normalized_or(g_out, -dir);
  s.contact_normal = n;
  s.lift_retrace = p.lift_retrace;

  Vec3 tangent = p.stroke_direction - n * dot(p.stroke_direction, n);
  tangent = normalized_or(tangent, normalized_or(cross(n, {0, 0, 1}), {1, 0, 0}));

  const Vec3 p0 = s.contact_point_m;
  const Vec3 start = p0 + n * p.approach_distance_m;
  double t = 0;
  auto add = [&](const Vec3& pos, double dt) {
    t += dt;
    s.waypoints.push_back({t, pos});
  };
  add(start, 0.0);
  add(start, p.rest_s);
  add(p0, p.approach_distance_m / p.approach_speed_m_s);
  s.t_press = t;
  const Vec3 pressed = p0 - n * p.press_depth_m;
  add(pressed, p.press_depth_m / p.press_speed_m_s);
  add(pressed, p.hold_s);
  s.t_stroke = t;
  // Stroke: keep the hand target press_depth below the surface under it, found by a
  // ray along -n from above each point of the straight tangent line.
  const double ds = std::max(0.5 * std::min({g.spacing_m.x, g.spacing_m.y, g.spacing_m.z}),
                             p.stroke_length_m / double(kMaxStrokeSteps));
  const int steps = std::max(1, int(std::ceil(p.stroke_length_m / ds)));
  Vec3 prev = pressed, last_surface = p0;
  for (int i = 1; i <= steps; ++i) {
    const double sl = p.stroke_length_m * i / steps;
    const Vec3 above = p0 + tangent * sl + n * p.approach_distance_m;
    Vec3 hit;
    if (find_surface(field, classify, above, -n, 3.0 * p.approach_distance_m + p.press_depth_m,
                     hit, kStrokeMarchSteps))
      last_surface = hit;
    else
      last_surface = p0 + tangent * sl;
    const Vec3 tgt = last_surface - n * p.press_depth_m;
    add(tgt, norm(tgt - prev) / p.stroke_speed_m_s);
    prev = tgt;
  }
  s.t_lift = t;
  const Vec3 up = last_surface + n * p.approach_distance_m;
  add(up, norm(up - prev) / p.approach_speed_m_s);
  add(up, p.rest_s);
  s.duration_s = t;
  return s;
}

}  // namespace isotouch::sim
