#include "isotouch/apps/sculpt/frame.h"

#include <algorithm>
#include <cmath>

namespace isotouch::sculpt {

using core::Vec3;

void CameraControl::orbit(double da, double de) {
  cam.azimuth_deg = std::fmod(cam.azimuth_deg + da, 360.0);
  cam.elevation_deg = std::clamp(cam.elevation_deg + de, -85.0, 85.0);
}

void CameraControl::pan(const engine::CameraView& view, const core::Grid& grid, double dx, double dy) {
  const Vec3 target = cam.target_m ? *cam.target_m : grid.centre_m();
  const double dist = norm(target - view.eye);
  const double h = 2.0 * dist * std::tan(view.fov_y_deg * 3.14159265358979323846 / 360.0);
  cam.target_m = target - view.right * (dx * h) + view.up * (dy * h);
}

void CameraControl::zoom_by(double f) {
  if (std::isfinite(f) && f > 0) cam.zoom = std::clamp(cam.zoom * f, 0.05, 50.0);
}

Ray cursor_ray(const engine::CameraView& view, int width, int height, double px, double py) {
  // pixel_direction takes whole pixels; interpolate between the four around (px, py).
  const int x0 = std::clamp(int(std::floor(px)), 0, width - 1), y0 = std::clamp(int(std::floor(py)), 0, height - 1);
  const double fx = std::clamp(px - x0, 0.0, 1.0), fy = std::clamp(py - y0, 0.0, 1.0);
  const int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
  const Vec3 d = engine::pixel_direction(view, width, height, x0, y0) * ((1 - fx) * (1 - fy)) +
                 engine::pixel_direction(view, width, height, x1, y0) * (fx * (1 - fy)) +
                 engine::pixel_direction(view, width, height, x0, y1) * ((1 - fx) * fy) +
                 engine::pixel_direction(view, width, height, x1, y1) * (fx * fy);
  return {view.eye, d / norm(d)};
}

std::array<float, 3> force_colour(double s) {
  s = std::clamp(std::isfinite(s) ? s : 1.0, 0.0, 1.0);
  if (s < 1.0 / 3) return {0.1f, float(0.3 + 2.1 * s), float(0.95 - 2.4 * s)};         // blue -> green
  if (s < 2.0 / 3) return {float(0.1 + 2.7 * (s - 1.0 / 3)), 1.0f, 0.15f};           // green -> yellow
  return {1.0f, float(1.0 - 2.5 * (s - 2.0 / 3)), 0.1f};                           // yellow -> red
}

std::vector<gpu::RaycastPrim> overlay_prims(const session::Observed& obs, const Vec3& hand_m, const ToolState& tool,
                                            double force_limit_n, double u, bool button_down) {
  std::vector<gpu::RaycastPrim> p;
  if (obs.tick < 0) return p;
  p.push_back(engine::prim_sphere(hand_m, 0.6 * u, {0.6f, 0.6f, 0.65f}, 0.8f, true));           // the hand
  p.push_back(engine::prim_sphere(obs.hip_m, 1.2 * u, {0.95f, 0.80f, 0.10f}, 1.0f, true));      // HIP
  p.push_back(engine::prim_sphere(obs.vhip_m, 1.0 * u, {0.15f, 0.80f, 0.25f}));                 // VHIP
  const double f = norm(obs.force_n);
  if (obs.contact && f > 1e-9 && std::isfinite(f)) {
    const Vec3 n = obs.force_n / f;
    p.push_back(engine::prim_disc(obs.vhip_m, n, 6.0 * u, {0.20f, 0.75f, 0.95f}, 0.40f));       // virtual plane
    const double s = f / std::max(force_limit_n, 1e-9);
    engine::add_arrow(p, obs.vhip_m, obs.vhip_m + n * (std::min(s, 1.5) * 12.0 * u + 2.0 * u), 0.35 * u,
                      force_colour(s));                                                          // force
  }
  // Brush footprint: the sphere the tool edits, around the VHIP (where it applies).
  std::array<float, 3> c{0.9f, 0.4f, 0.3f};
  switch (tool.kind) {
    case session::BrushKind::kAdd: c = {0.3f, 0.9f, 0.4f}; break;
    case session::BrushKind::kCarve: c = {0.95f, 0.45f, 0.3f}; break;
    case session::BrushKind::kSmooth: c = {0.4f, 0.6f, 1.0f}; break;
    case session::BrushKind::kDrill: c = {0.9f, 0.3f, 0.9f}; break;
  }
  p.push_back(engine::prim_sphere(obs.contact ? obs.vhip_m : obs.hip_m, tool.radius_m, c, button_down ? 0.35f : 0.18f));
  return p;
}

}  // namespace isotouch::sculpt
