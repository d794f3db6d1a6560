// object_box.cpp - the object's box in its scan; see object_box.h.
#include "isotouch/run/object_box.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <numbers>
#include <vector>

namespace isotouch::run {
using core::Vec3;

namespace {

/// One 6-connected component: its voxel count and index box.
struct Component {
  std::size_t voxels = 0;
  int lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
};

/// Voxel states while labelling: outside (or not finite), inside and not yet reached, reached.
enum : std::uint8_t { kOut = 0, kIn = 1, kSeen = 2 };

std::vector<std::uint8_t> inside_mask(const engine::Volume& vol, const core::Isosurface& iso) {
  std::vector<std::uint8_t> m(vol.voxels.size(), kOut);
  for (std::size_t i = 0; i < m.size(); ++i) {
    const float v = vol.voxels[i];
    if (std::isfinite(v) && iso.contains(v)) m[i] = kIn;
  }
  return m;
}

/// The component holding voxel `seed` (breadth first, the queue holds the front only); marks it seen.
Component flood(std::vector<std::uint8_t>& m, const core::Grid& g, std::size_t seed) {
  const int nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  const std::size_t sx = 1, sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);
  Component c;
  c.lo[0] = c.hi[0] = int(seed % sy), c.lo[1] = c.hi[1] = int((seed / sy) % std::size_t(ny));
  c.lo[2] = c.hi[2] = int(seed / sz);
  std::deque<std::size_t> front{seed};
  m[seed] = kSeen;
  while (!front.empty()) {
    const std::size_t i = front.front();
    front.pop_front();
    ++c.voxels;
    const int p[3] = {int(i % sy), int((i / sy) % std::size_t(ny)), int(i / sz)};
    for (int a = 0; a < 3; ++a) c.lo[a] = std::min(c.lo[a], p[a]), c.hi[a] = std::max(c.hi[a], p[a]);
    const auto visit = [&](bool ok, std::size_t j) {
      if (ok && m[j] == kIn) m[j] = kSeen, front.push_back(j);
    };
    visit(p[0] > 0, i - sx), visit(p[0] + 1 < nx, i + sx);
    visit(p[1] > 0, i - sy), visit(p[1] + 1 < ny, i + sy);
    visit(p[2] > 0, i - sz), visit(p[2] + 1 < nz, i + sz);
  }
  return c;
}

}  // namespace

std::optional<ObjectBox> object_box(const engine::Volume& vol, const core::Isosurface& iso) {
  std::vector<std::uint8_t> m = inside_mask(vol, iso);
  std::vector<Component> parts;
  for (std::size_t i = 0; i < m.size(); ++i)
    if (m[i] == kIn) parts.push_back(flood(m, vol.grid, i));
  if (parts.empty()) return std::nullopt;
  std::size_t largest = 0;
  for (const Component& c : parts) largest = std::max(largest, c.voxels);
  int lo[3] = {vol.grid.dims[0], vol.grid.dims[1], vol.grid.dims[2]}, hi[3] = {-1, -1, -1};
  for (const Component& c : parts)
    if (100 * c.voxels >= largest)
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c.lo[a]), hi[a] = std::max(hi[a], c.hi[a]);
  const Vec3 o = vol.grid.origin_m, s = vol.grid.spacing_m;
  return ObjectBox{Vec3{o.x + s.x * lo[0], o.y + s.y * lo[1], o.z + s.z * lo[2]},
                   Vec3{o.x + s.x * hi[0], o.y + s.y * hi[1], o.z + s.z * hi[2]}};
}

engine::OrbitCamera frame_object(engine::OrbitCamera cam, const engine::Volume& vol, const core::Isosurface& iso) {
  const auto box = object_box(vol, iso);
  if (!box) return cam;
  cam.target_m = (box->low + box->high) * 0.5;
  if (cam.distance_m == 0) {
    const Vec3 ext = box->high - box->low + vol.grid.spacing_m * 2.0;
    cam.distance_m = 0.5 * core::norm(ext) / std::sin(0.5 * cam.fov_y_deg * std::numbers::pi / 180.0) * 1.02;
  }
  return cam;
}

}  // namespace isotouch::run
