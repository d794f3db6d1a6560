#include "isotouch/run/drill_figure.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "isotouch/engine/raycast.h"
#include "isotouch/run/picture.h"

namespace isotouch::run {
using core::Vec3;
namespace {

using core::Vec3;

constexpr double kPi = 3.14159265358979323846;
constexpr double kFovDeg = 30;

/// The volume's superior direction in grid-world: D^T up_phys (D orthonormal).
Vec3 grid_up(const engine::Volume& vol) {
  const Vec3 u = default_camera(vol).up_phys;
  const auto& d = vol.direction;
  return {d[0] * u.x + d[3] * u.y + d[6] * u.z, d[1] * u.x + d[4] * u.y + d[7] * u.z,
          d[2] * u.x + d[5] * u.y + d[8] * u.z};
}

engine::CameraView site_view(const DrillSite& s, const Vec3& up, double half_width_m) {
  const double dist = half_width_m / std::tan(0.5 * kFovDeg * kPi / 180);
  Vec3 u = up - s.outward * core::dot(up, s.outward);
  if (core::norm(u) < 1e-6) u = std::abs(s.outward.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  return engine::look_at(s.point_m + s.outward * dist, s.point_m, u, kFovDeg);
}

/// A ring of small spheres around the site, in the tangent plane, drawn through the surface.
std::vector<gpu::RaycastPrim> ring_marker(const DrillSite& s, double size_m) {
  const Vec3 a = core::normalized_or(core::cross(s.outward, std::abs(s.outward.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0}),
                                     Vec3{1, 0, 0});
  const Vec3 b = core::cross(s.outward, a);
  const double r = std::max(2.0 * s.brush_radius_m, 4 * size_m);
  std::vector<gpu::RaycastPrim> p;
  for (int i = 0; i < 32; ++i) {
    const double t = 2 * kPi * i / 32;
    p.push_back(engine::prim_sphere(s.point_m + (a * std::cos(t) + b * std::sin(t)) * r + s.outward * size_m, 0.45 * size_m,
                                    {1.0f, 0.62f, 0.05f}, 1.0f, true));
  }
  return p;
}

/// Copies `src` into `dst` (width dw) at (x0, y0).
void blit(std::vector<std::uint32_t>& dst, int dw, const engine::RaycastImage& src, int x0, int y0) {
  for (int y = 0; y < src.height; ++y)
    std::copy_n(src.rgba.begin() + std::ptrdiff_t(y) * src.width, src.width,
                dst.begin() + std::ptrdiff_t(y0 + y) * dw + x0);
}

void frame(std::vector<std::uint32_t>& dst, int dw, int x0, int y0, int size, int thick, std::uint32_t colour) {
  for (int y = y0 - thick; y < y0 + size + thick; ++y)
    for (int x = x0 - thick; x < x0 + size + thick; ++x) {
      const bool inside = x >= x0 && x < x0 + size && y >= y0 && y < y0 + size;
      if (!inside) dst[std::size_t(y) * std::size_t(dw) + std::size_t(x)] = colour;
    }
}

}  // namespace

std::string draw_drill_figure(engine::VulkanContext* vk, const engine::Volume& before, const engine::Volume& after,
                              const core::Isosurface& iso, const DrillSite& site, const std::string& out_png,
                              const DrillFigureLayout& l) {
  try {
    const Vec3 up = grid_up(before);
    const double size = probe_size_m(before.grid);
    const engine::CameraView wide = site_view(site, up, l.wide_half_width_m);
    const engine::CameraView zoom =
        site_view(site, up, std::max(l.zoom_half_width_brush * site.brush_radius_m, 4 * size));
    const int W = 2 * l.panel_width + l.gap, H = l.panel_height;
    std::vector<std::uint32_t> out(std::size_t(W) * std::size_t(H), engine::pack_rgba8(1.0f, 1.0f, 1.0f));
    const engine::Volume* vols[2] = {&before, &after};
    for (int i = 0; i < 2; ++i) {
      const float bg = float(iso.outside_value(vols[i]->min_value, vols[i]->max_value));
      const engine::RaycastField field = engine::make_raycast_field(vols[i]->grid, vols[i]->voxels, iso, bg);
      PictureRequest req;
      req.width = l.panel_width;
      req.height = l.panel_height;
      req.view = wide;
      req.prims = ring_marker(site, size);
      const engine::RaycastImage w = render_picture(vk, field, vols[i]->direction, req, "");
      req.width = req.height = l.inset;
      req.view = zoom;
      req.prims.clear();
      const engine::RaycastImage z = render_picture(vk, field, vols[i]->direction, req, "");
      const int x0 = i * (l.panel_width + l.gap);
      blit(out, W, w, x0, 0);
      const int ix = x0 + l.panel_width - l.inset - 6, iy = 6;
      blit(out, W, z, ix, iy);
      frame(out, W, ix, iy, l.inset, 3, engine::pack_rgba8(1.0f, 0.62f, 0.05f));
    }
    write_png(out_png, W, H, out);
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

}  // namespace isotouch::run
