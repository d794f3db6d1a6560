#include "script.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "sampling.h"

namespace isotouch::servo {

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

bool find_surface(const SampleField& field, const HriRenderer& r, const Vec3& origin,
                  const Vec3& dir, double max_dist, Vec3& hit) {
  const Vec3& sp = field.grid.spacing_m;
  const double step = 0.25 * std::min({sp.x, sp.y, sp.z});
  if (r.excess(sample_value(field, origin)) > 0.0) return false;
  double t_out = 0.0;
  for (double t = step; t <= max_dist; t += step) {
    if (r.excess(sample_value(field, origin + dir * t)) > 0.0) {
      double lo = t_out, hi = t;
      for (int i = 0; i < 50; ++i) {
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
  const Vec3 origin{lo.x + p.ray_origin_frac.x * ext.x, lo.y + p.ray_origin_frac.y * ext.y,
                    lo.z + p.ray_origin_frac.z * ext.z};
  const Vec3 dir = normalized_or(p.ray_direction, {});
  auto describe = [&] {
    std::ostringstream s;
    s << "script: the ray from (" << origin.x << ", " << origin.y << ", " << origin.z
      << ") m along (" << dir.x << ", " << dir.y << ", " << dir.z << ")";
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
  const Vec3 g_out = hri.inside == InsideIs::kAbove ? -fv.gradient : fv.gradient;
  const Vec3 n = normalized_or(g_out, -dir);
  s.contact_normal = n;

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
  const double ds = 0.5 * std::min({g.spacing_m.x, g.spacing_m.y, g.spacing_m.z});
  const int steps = std::max(1, int(std::ceil(p.stroke_length_m / ds)));
  Vec3 prev = pressed, last_surface = p0;
  for (int i = 1; i <= steps; ++i) {
    const double sl = p.stroke_length_m * i / steps;
    const Vec3 above = p0 + tangent * sl + n * p.approach_distance_m;
    Vec3 hit;
    if (find_surface(field, classify, above, -n, 3.0 * p.approach_distance_m + p.press_depth_m,
                     hit))
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

}  // namespace isotouch::servo
