// raycast_view.cpp - what the ray caster is asked to draw (engine/raycast.h): cameras (look_at,
// orbit_view), a frame's parameters for the shaders (make_params), and the overlay's primitives.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/engine/raycast.h"
#include "isotouch/engine/raycast_detail.h"

namespace isotouch::engine {

namespace raycast_detail {
void set3(float& x, float& y, float& z, const Vec3& v) {
  x = float(v.x);
  y = float(v.y);
  z = float(v.z);
}
}  // namespace raycast_detail

using namespace raycast_detail;

namespace {

constexpr double kPi = 3.14159265358979323846;

Vec3 unit(const Vec3& v, const char* what) {
  const double n = norm(v);
  if (!(n > 0) || !std::isfinite(n)) throw std::invalid_argument(std::string("raycast: ") + what + " has no direction");
  return v / n;
}

/// D^T v: a physical-frame vector in grid-world axes (D orthonormal, row-major).
Vec3 physical_to_grid(const std::array<double, 9>& D, const Vec3& v) {
  return {D[0] * v.x + D[3] * v.y + D[6] * v.z, D[1] * v.x + D[4] * v.y + D[7] * v.z,
          D[2] * v.x + D[5] * v.y + D[8] * v.z};
}
}  // namespace

CameraView look_at(const Vec3& eye, const Vec3& target, const Vec3& up, double fov_y_deg) {
  CameraView v;
  v.eye = eye;
  v.forward = unit(target - eye, "look_at: target - eye");
  v.right = unit(cross(v.forward, up), "look_at: up (parallel to the view direction)");
  v.up = cross(v.right, v.forward);
  v.fov_y_deg = fov_y_deg;
  return v;
}

namespace {
double determinant(const std::array<double, 9>& D) {
  return D[0] * (D[4] * D[8] - D[5] * D[7]) - D[1] * (D[3] * D[8] - D[5] * D[6]) + D[2] * (D[3] * D[7] - D[4] * D[6]);
}
}  // namespace

CameraView orbit_view(const core::Grid& grid, const std::array<double, 9>& D, const OrbitCamera& cam) {
  if (!(cam.elevation_deg > -90 && cam.elevation_deg < 90))
    throw std::invalid_argument("camera: elevation must be in (-90, 90) degrees, got " + std::to_string(cam.elevation_deg));
  if (!(cam.fov_y_deg > 0 && cam.fov_y_deg < 170))
    throw std::invalid_argument("camera: field of view must be in (0, 170) degrees, got " + std::to_string(cam.fov_y_deg));
  if (!(cam.zoom > 0 && std::isfinite(cam.zoom)))
    throw std::invalid_argument("camera: zoom must be > 0, got " + std::to_string(cam.zoom));
  if (!(cam.distance_m >= 0 && std::isfinite(cam.distance_m)) || !std::isfinite(cam.azimuth_deg))
    throw std::invalid_argument("camera: distance must be >= 0 m and azimuth finite");
  const Vec3 target = cam.target_m.value_or(grid.centre_m());
  double dist = cam.distance_m;
  if (dist == 0) {
    // Fit the bounding sphere of the box of voxel centres (plus the border band).
    const Vec3 ext = grid.extent_m() + grid.spacing_m * 2.0;
    const double radius = 0.5 * norm(ext);
    dist = radius / std::sin(0.5 * cam.fov_y_deg * kPi / 180.0) * 1.02;
  }
  dist /= cam.zoom;
  const double az = cam.azimuth_deg * kPi / 180, el = cam.elevation_deg * kPi / 180;
  // Physical frame: eye direction from the target; azimuth 0 = the front side.
  const Vec3 upp = unit(cam.up_phys, "camera up");
  const Vec3 front = unit(cam.front_phys - upp * dot(cam.front_phys, upp), "camera front (along up)");
  const Vec3 side = cross(upp, front);
  const Vec3 eye_dir_phys =
      (front * std::cos(az) + side * std::sin(az)) * std::cos(el) + upp * std::sin(el);
  const Vec3 eye_dir = physical_to_grid(D, eye_dir_phys);
  const Vec3 up = physical_to_grid(D, upp);
  CameraView v = look_at(target + eye_dir * dist, target, up, cam.fov_y_deg);
  // look_at's right (forward x up) is taken in the grid frame, which a reflection D (det < 0:
  // a scan whose slices run inferior, a radiological NIfTI) mirrors: reversed, the picture
  // shows the physical volume, not its mirror image.
  if (determinant(D) < 0) v.right = v.right * -1.0;
  return v;
}

double voxels_per_metre(const core::Grid& g, const Vec3& dir) {
  return norm(Vec3{dir.x / g.spacing_m.x, dir.y / g.spacing_m.y, dir.z / g.spacing_m.z});
}

Vec3 pixel_direction(const CameraView& view, int width, int height, int px, int py) {
  const double focal = 0.5 * height / std::tan(0.5 * view.fov_y_deg * kPi / 180);
  const double sx = (px + 0.5) - 0.5 * width, sy = 0.5 * height - (py + 0.5);
  return unit(view.forward * focal + view.right * sx + view.up * sy, "pixel direction");
}

std::uint32_t style_flags(const RaycastStyle& s) {
  return (s.skip_empty ? ISOTOUCH_RAYCAST_SKIP : 0u) | (s.clip ? ISOTOUCH_RAYCAST_CLIP : 0u) |
         (s.skip_empty && s.tile_starts ? ISOTOUCH_RAYCAST_TILES : 0u);
}

gpu::RaycastParams make_params(const RaycastField& f, const CameraView& v, const RaycastStyle& s, int width,
                               int height) {
  if (width < 1 || height < 1 || width > 8192 || height > 8192)
    throw std::invalid_argument("raycast: image size must be 1..8192 pixels per side, got " + std::to_string(width) +
                                " x " + std::to_string(height));
  if (!(s.step_vox > 0.01f && s.step_vox <= ISOTOUCH_RAYCAST_MAX_STEP))
    throw std::invalid_argument("raycast: step must be in (0.01, " + std::to_string(ISOTOUCH_RAYCAST_MAX_STEP) +
                                "] voxels (the refinement reads the 3x3x3 voxels around one step), got " +
                                std::to_string(s.step_vox));
  // A ray's lattice has at most ceil(diagonal of the box [-1, n] / step) + 1 samples.
  const auto& dims = f.grid.dims;
  const double diag = std::sqrt(double(dims[0] + 1) * (dims[0] + 1) + double(dims[1] + 1) * (dims[1] + 1) +
                                double(dims[2] + 1) * (dims[2] + 1));
  if (diag / s.step_vox + 2 > ISOTOUCH_RAYCAST_MAX_SAMPLES)
    throw std::invalid_argument("raycast: step " + std::to_string(s.step_vox) + " voxel on a " + std::to_string(dims[0]) +
                                "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " grid needs up to " +
                                std::to_string(long(diag / s.step_vox + 2)) + " samples per ray, more than " +
                                std::to_string(ISOTOUCH_RAYCAST_MAX_SAMPLES) +
                                " (llvmpipe ends an invocation's loops after 65535 iterations); use a step >= " +
                                std::to_string(diag / (ISOTOUCH_RAYCAST_MAX_SAMPLES - 2)) + " voxel");
  gpu::RaycastParams p{};
  p.width = std::uint32_t(width);
  p.height = std::uint32_t(height);
  p.nx = std::uint32_t(f.grid.dims[0]);
  p.ny = std::uint32_t(f.grid.dims[1]);
  p.nz = std::uint32_t(f.grid.dims[2]);
  p.bx = std::uint32_t(f.bricks[0]);
  p.by = std::uint32_t(f.bricks[1]);
  p.bz = std::uint32_t(f.bricks[2]);
  p.tau = float(f.iso.tau);
  p.inside_sign = f.iso.inside == core::InsideIs::kAbove ? 1.0f : -1.0f;
  p.background = f.background;
  p.step_vox = s.step_vox;
  set3(p.eye_x, p.eye_y, p.eye_z, v.eye);
  p.focal_px = float(0.5 * height / std::tan(0.5 * v.fov_y_deg * kPi / 180));
  set3(p.fwd_x, p.fwd_y, p.fwd_z, v.forward);
  set3(p.right_x, p.right_y, p.right_z, v.right);
  set3(p.up_x, p.up_y, p.up_z, v.up);
  set3(p.origin_x, p.origin_y, p.origin_z, f.grid.origin_m);
  set3(p.inv_sp_x, p.inv_sp_y, p.inv_sp_z,
       {1.0 / f.grid.spacing_m.x, 1.0 / f.grid.spacing_m.y, 1.0 / f.grid.spacing_m.z});
  if (s.clip) {
    const Vec3 n = unit(s.clip->normal, "clip plane normal");
    set3(p.clip_nx, p.clip_ny, p.clip_nz, n);
    p.clip_d = float(-dot(n, s.clip->point_m));
  }
  set3(p.surf_r, p.surf_g, p.surf_b, {s.surface[0], s.surface[1], s.surface[2]});
  set3(p.bg_r, p.bg_g, p.bg_b, {s.background[0], s.background[1], s.background[2]});
  set3(p.cap_r, p.cap_g, p.cap_b, {s.cap[0], s.cap[1], s.cap[2]});
  set3(p.act_lo_x, p.act_lo_y, p.act_lo_z, {-1, -1, -1});
  set3(p.act_hi_x, p.act_hi_y, p.act_hi_z, {double(dims[0]), double(dims[1]), double(dims[2])});
  return p;
}

namespace {
gpu::RaycastPrim prim(std::uint32_t kind, const Vec3& a, const Vec3& b, double r, std::array<float, 3> rgb,
                      float alpha, bool xray) {
  if (!(r > 0) || !std::isfinite(r)) throw std::invalid_argument("raycast: primitive radius must be > 0 m");
  gpu::RaycastPrim q{};
  q.kind = kind;
  q.r0 = float(r);
  q.alpha = alpha;
  q.pad0 = xray ? 1.0f : 0.0f;
  set3(q.ax, q.ay, q.az, a);
  set3(q.bx, q.by, q.bz, b);
  q.cr = rgb[0];
  q.cg = rgb[1];
  q.cb = rgb[2];
  return q;
}
}  // namespace

gpu::RaycastPrim prim_sphere(const Vec3& c, double r, std::array<float, 3> rgb, float alpha, bool xray) {
  return prim(ISOTOUCH_RAYCAST_PRIM_SPHERE, c, c, r, rgb, alpha, xray);
}
gpu::RaycastPrim prim_disc(const Vec3& c, const Vec3& n, double r, std::array<float, 3> rgb, float alpha) {
  return prim(ISOTOUCH_RAYCAST_PRIM_DISC, c, unit(n, "disc normal"), r, rgb, alpha, false);
}
gpu::RaycastPrim prim_capsule(const Vec3& a, const Vec3& b, double r, std::array<float, 3> rgb, float alpha,
                              bool xray) {
  return prim(ISOTOUCH_RAYCAST_PRIM_CAPSULE, a, b, r, rgb, alpha, xray);
}
gpu::RaycastPrim prim_cone(const Vec3& base, const Vec3& apex, double r, std::array<float, 3> rgb) {
  return prim(ISOTOUCH_RAYCAST_PRIM_CONE, base, apex, r, rgb, 1.0f, false);
}
void add_arrow(std::vector<gpu::RaycastPrim>& prims, const Vec3& from, const Vec3& to, double shaft_r,
               std::array<float, 3> rgb) {
  const Vec3 d = to - from;
  if (!(norm(d) > 0)) return;
  const Vec3 neck = from + d * 0.75;
  prims.push_back(prim_capsule(from, neck, shaft_r, rgb));
  prims.push_back(prim_cone(neck, to, shaft_r * 2.5, rgb));
}
}  // namespace isotouch::engine
