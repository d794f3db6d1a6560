// brush_cpu.cpp - the brush model's host side (validation, brick box, push constants) and
// the one-thread CPU reference of shaders/brush.comp (see brush.h for the model).
// Compiled with -ffp-contract=off (engine/CMakeLists.txt): no FMA contraction, the same
// float operations in the same order as the shader's `precise` ones.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>

#include "isotouch/core/brick_field.h"
#include "isotouch/session/brush.h"

namespace isotouch::session {
using engine::Volume;
using engine::VolumeError;

const char* to_string(BrushKind k) {
  switch (k) {
    case BrushKind::kAdd: return "add";
    case BrushKind::kCarve: return "carve";
    case BrushKind::kSmooth: return "smooth";
    case BrushKind::kDrill: return "drill";
  }
  return "unknown";
}

BrushTargets default_targets(const Volume& vol, const core::Isosurface& iso) {
  const double lo = vol.min_value, hi = vol.max_value;
  BrushTargets t;
  const bool above = iso.inside == core::InsideIs::kAbove;
  double material = above ? std::max(hi, iso.tau) : std::min(lo, iso.tau);
  const double empty = iso.outside_value(lo, hi);
  // A volume with no material (a blank canvas: hi <= tau for "above") would give material
  // = tau, which is not inside (contains() is strict): push it one data span (at least 1
  // value unit) past tau so that "add" creates material.
  if (!iso.contains(material)) {
    const double span = std::max(std::abs(iso.tau - empty), 1.0);
    material = above ? iso.tau + span : iso.tau - span;
  }
  t.material = float(material);
  t.empty = float(empty);
  const double span = std::abs(double(t.material) - double(t.empty));
  t.density_scale = span > 0 && std::isfinite(span) ? float(span) : 1.0f;
  return t;
}

namespace {
std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
bool finite3(const core::Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
double drill_amount(const Brush& b) { return b.rate * b.dt_s * std::max(0.0, b.force_n - b.force_threshold_n); }
}  // namespace

std::string validate(const Brush& b) {
  const std::string k = std::string("brush (") + to_string(b.kind) + "): field '";
  if (unsigned(b.kind) > 3u) return "brush: field 'kind' = " + std::to_string(unsigned(b.kind)) + " is not a brush";
  if (!finite3(b.centre_m))
    return k + "centre_m' must be finite, got " + num(b.centre_m.x) + " " + num(b.centre_m.y) + " " + num(b.centre_m.z);
  if (!(b.radius_m > 0) || !std::isfinite(b.radius_m) || b.radius_m > 10.0)
    return k + "radius_m' must be in (0, 10] m, got " + num(b.radius_m);
  if (!(b.falloff > 0 && b.falloff <= 1)) return k + "falloff' must be in (0, 1], got " + num(b.falloff);
  if (b.kind == BrushKind::kSmooth) {
    if (!(b.strength >= 0 && b.strength <= 1)) return k + "strength' must be in [0, 1] for smooth, got " + num(b.strength);
  } else if (!(b.strength >= 0) || !std::isfinite(float(b.strength))) {
    return k + "strength' must be a finite float >= 0 [value units], got " + num(b.strength);
  }
  if (!std::isfinite(b.targets.material) || !std::isfinite(b.targets.empty))
    return k + "targets' material and empty must be finite, got " + num(b.targets.material) + ", " +
           num(b.targets.empty);
  if (!(b.targets.density_scale > 0) || !std::isfinite(b.targets.density_scale))
    return k + "targets.density_scale' must be finite and > 0, got " + num(b.targets.density_scale);
  if (b.kind == BrushKind::kDrill) {
    const std::pair<const char*, double> f[] = {
        {"force_n", b.force_n}, {"force_threshold_n", b.force_threshold_n}, {"rate", b.rate}, {"dt_s", b.dt_s}};
    for (const auto& [name, v] : f)
      if (!(v >= 0) || !std::isfinite(v)) return k + name + "' must be finite and >= 0, got " + num(v);
    if (!std::isfinite(float(drill_amount(b))))
      return k + "rate' * dt_s * (force_n - force_threshold_n) overflows a float: " + num(drill_amount(b));
  }
  return {};
}

BrickRange touched_range(const core::Grid& g, const Brush& b) {
  BrickRange r;
  if (g.empty()) return r;
  const double c[3] = {(b.centre_m.x - g.origin_m.x) / g.spacing_m.x, (b.centre_m.y - g.origin_m.y) / g.spacing_m.y,
                       (b.centre_m.z - g.origin_m.z) / g.spacing_m.z};
  const double s[3] = {g.spacing_m.x, g.spacing_m.y, g.spacing_m.z};
  for (std::size_t a = 0; a < 3; ++a) {
    const double reach = b.radius_m / s[a];
    // One voxel of margin on each side: the float distance test may round a voxel at
    // exactly the radius inside; the dispatch must cover every voxel the test accepts.
    const double lo = std::max(std::floor(c[a] - reach) - 1.0, 0.0);
    const double hi = std::min(std::ceil(c[a] + reach) + 1.0, double(g.dims[a] - 1));
    if (!(lo <= hi)) return BrickRange{};
    r.lo[a] = int(lo) / core::kBrickSize;
    r.hi[a] = int(hi) / core::kBrickSize + 1;
  }
  return r;
}

std::vector<std::uint32_t> touched_bricks(const core::Grid& g, const Brush& b) {
  const BrickRange r = touched_range(g, b);
  std::vector<std::uint32_t> ids;
  if (r.empty()) return ids;
  ids.reserve(r.count());
  const auto nb = core::brick_counts(g);
  for (int z = r.lo[2]; z < r.hi[2]; ++z)
    for (int y = r.lo[1]; y < r.hi[1]; ++y)
      for (int x = r.lo[0]; x < r.hi[0]; ++x)
        ids.push_back(std::uint32_t((std::size_t(z) * std::size_t(nb[1]) + std::size_t(y)) * std::size_t(nb[0]) +
                                    std::size_t(x)));
  return ids;
}

PreBox pre_box(const core::Grid& g, const BrickRange& r) {
  PreBox p;
  for (std::size_t a = 0; a < 3; ++a) {
    p.lo[a] = std::max(r.lo[a] * core::kBrickSize - 1, 0);
    p.hi[a] = std::min(r.hi[a] * core::kBrickSize + 1, g.dims[a]);
  }
  return p;
}

gpu::BrushPush make_brush_push(const core::Grid& g, const Brush& b) {
  gpu::BrushPush p{};
  p.nx = gpu::uint(g.dims[0]);
  p.ny = gpu::uint(g.dims[1]);
  p.nz = gpu::uint(g.dims[2]);
  p.kind = gpu::uint(b.kind);
  const core::Vec3 c = g.to_index(b.centre_m);
  p.cx = float(c.x);
  p.cy = float(c.y);
  p.cz = float(c.z);
  p.sx = float(g.spacing_m.x);
  p.sy = float(g.spacing_m.y);
  p.sz = float(g.spacing_m.z);
  const double inner = b.radius_m * (1.0 - b.falloff);
  p.radius = float(b.radius_m);
  p.inner = float(inner);
  p.inv_width = float(1.0 / (b.radius_m - inner));
  p.amount = float(b.kind == BrushKind::kDrill ? drill_amount(b) : b.strength);
  p.target = b.kind == BrushKind::kAdd ? b.targets.material : b.targets.empty;
  p.dens_sign = b.targets.material >= b.targets.empty ? 1.0f : -1.0f;
  p.inv_dens_scale = float(1.0 / double(b.targets.density_scale));
  return p;
}

namespace {
float toward(float v, float target, float step) {
  if (v < target) return std::min(v + step, target);
  if (v > target) return std::max(v - step, target);
  return v;
}

/// Weight w(r) of voxel (x, y, z); false if the voxel is outside the brush (w = 0).
bool weight(const gpu::BrushPush& p, int x, int y, int z, float& w) {
  const float dx = (float(x) - p.cx) * p.sx;
  const float dy = (float(y) - p.cy) * p.sy;
  const float dz = (float(z) - p.cz) * p.sz;
  const float r = std::sqrt((dx * dx + dy * dy) + dz * dz);
  if (!(r < p.radius)) return false;
  float t = (r - p.inner) * p.inv_width;
  t = std::min(std::max(t, 0.0f), 1.0f);
  w = 1.0f - (t * t) * (3.0f - 2.0f * t);
  return true;
}

/// Pre-edit copy of the box (smooth reads the neighbours from it), x fastest.
struct PreEdit {
  PreBox box;
  std::vector<float> v;
};

/// The drill's per-material constants: per material id, the removal per application and
/// 1 / density scale (float, computed once as make_brush_push does for the brush's own),
/// and which ids are critical. Id 0 takes the brush's own (p.amount, p.inv_dens_scale).
struct CutConstants {
  std::vector<float> amount, inv_dens;
  std::vector<std::uint8_t> critical;
};
CutConstants cut_constants(const Brush& b, const gpu::BrushPush& p, const MaterialCut& cut) {
  CutConstants c;
  // Every id has an entry: one past the table (refused by validate(), which the Sculptor runs
  // once) is left unchanged, as a critical one.
  const std::size_t n = cut.table.size() + 1;
  c.amount.assign(256, p.amount);
  c.inv_dens.assign(256, p.inv_dens_scale);
  c.critical.assign(256, 1);
  std::fill(c.critical.begin(), c.critical.begin() + std::ptrdiff_t(n), std::uint8_t(0));
  const double excess = std::max(0.0, b.force_n - b.force_threshold_n);
  for (std::size_t i = 1; i < n; ++i) {
    const CutMaterial& m = cut.table[i - 1];
    if (b.kind == BrushKind::kDrill && m.rate >= 0) c.amount[i] = float(m.rate * b.dt_s * excess);
    if (m.density_scale > 0) c.inv_dens[i] = float(1.0 / m.density_scale);
    c.critical[i] = m.critical ? 1 : 0;
  }
  return c;
}

float new_value(const gpu::BrushPush& p, const core::Grid& g, const PreEdit& pre, int x, int y, int z, float v,
                float w) {
  switch (p.kind) {
    case ISOTOUCH_BRUSH_ADD:
    case ISOTOUCH_BRUSH_CARVE: return toward(v, p.target, p.amount * w);
    case ISOTOUCH_BRUSH_DRILL: {
      const float f = 1.0f + std::max((v - p.target) * p.dens_sign, 0.0f) * p.inv_dens_scale;
      return toward(v, p.target, (p.amount * w) / f);
    }
    default: {  // smooth
      auto at = [&](int i, int j, int k) {
        i = std::clamp(i, 0, g.dims[0] - 1);
        j = std::clamp(j, 0, g.dims[1] - 1);
        k = std::clamp(k, 0, g.dims[2] - 1);
        const auto& bx = pre.box;
        return pre.v[(std::size_t(k - bx.lo[2]) * std::size_t(bx.hi[1] - bx.lo[1]) + std::size_t(j - bx.lo[1])) *
                         std::size_t(bx.hi[0] - bx.lo[0]) + std::size_t(i - bx.lo[0])];
      };
      const float sum = ((((at(x - 1, y, z) + at(x + 1, y, z)) + at(x, y - 1, z)) + at(x, y + 1, z)) +
                         at(x, y, z - 1)) + at(x, y, z + 1);
      const float m = sum * (1.0f / 6.0f);
      // A NaN/Inf neighbour leaves the voxel as it is (smoothing must not spread NaN holes).
      if (!std::isfinite(m)) return v;
      return v + (m - v) * (p.amount * w);
    }
  }
}
}  // namespace

std::string validate(const MaterialCut& cut, std::size_t voxels) {
  if (cut.ids.size() != voxels)
    return "material cut: field 'ids' holds " + std::to_string(cut.ids.size()) + " labels for a volume of " +
           std::to_string(voxels) + " voxels";
  if (cut.table.size() > 255) return "material cut: field 'table' has " + std::to_string(cut.table.size()) + " materials (at most 255)";
  for (std::size_t i = 0; i < cut.table.size(); ++i) {
    const CutMaterial& m = cut.table[i];
    const std::string f = "material cut: material " + std::to_string(i + 1) + ": field '";
    if (!std::isfinite(m.rate) || !std::isfinite(float(m.rate)))
      return f + "rate' must be finite (< 0: the brush's), got " + num(m.rate);
    if (!(m.density_scale >= 0) || !std::isfinite(m.density_scale) ||
        (m.density_scale > 0 && !std::isfinite(float(1.0 / m.density_scale))))
      return f + "density_scale' must be 0 or a finite value whose inverse is a finite float, got " + num(m.density_scale);
  }
  for (std::size_t v = 0; v < cut.ids.size(); ++v)
    if (cut.ids[v] > cut.table.size())
      return "material cut: field 'ids': voxel " + std::to_string(v) + " has label " + std::to_string(cut.ids[v]) +
             ", past the " + std::to_string(cut.table.size()) + " materials";
  return {};
}

BrushResult apply_brush_cpu(Volume& vol, const Brush& b, const MaterialCut* cut) {
  const auto t0 = std::chrono::steady_clock::now();
  if (std::string e = validate(b); !e.empty()) throw BrushError(e);
  // The labels' ids are checked once (Sculptor::set_material_cut): here the sizes only (an id
  // past the table is left unchanged, never read past an array).
  if (cut && cut->ids.size() != vol.voxels.size())
    throw BrushError(vol.path + ": material cut: field 'ids' holds " + std::to_string(cut->ids.size()) +
                     " labels for a volume of " + std::to_string(vol.voxels.size()) + " voxels");
  if (cut && cut->table.size() > 255)
    throw BrushError(vol.path + ": material cut: field 'table' has " + std::to_string(cut->table.size()) + " materials (at most 255)");
  const core::Grid& g = vol.grid;
  if (g.empty() || vol.voxels.size() != g.voxel_count())
    throw VolumeError(vol.path + ": brush: " + std::to_string(vol.voxels.size()) + " voxels for dims " +
                      std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" + std::to_string(g.dims[2]));
  BrushResult res;
  const BrickRange r = touched_range(g, b);
  res.touched = touched_bricks(g, b);
  if (r.empty()) return res;
  const gpu::BrushPush p = make_brush_push(g, b);
  PreEdit pre;
  if (b.kind == BrushKind::kSmooth) {
    pre.box = pre_box(g, r);
    const PreBox& bx = pre.box;
    const std::size_t w = std::size_t(bx.hi[0] - bx.lo[0]);
    pre.v.resize(w * std::size_t(bx.hi[1] - bx.lo[1]) * std::size_t(bx.hi[2] - bx.lo[2]));
    std::size_t k = 0;
    for (int z = bx.lo[2]; z < bx.hi[2]; ++z)
      for (int y = bx.lo[1]; y < bx.hi[1]; ++y, k += w)
        std::memcpy(pre.v.data() + k, vol.voxels.data() + g.index(bx.lo[0], y, z), w * sizeof(float));
  }
  // Every brush leaves a critical voxel as it is; the removing brushes take each material's
  // rate and density factor.
  const bool per_material = cut && (b.kind == BrushKind::kDrill || b.kind == BrushKind::kCarve);
  const CutConstants cc = cut ? cut_constants(b, p, *cut) : CutConstants{};
  gpu::BrushPush pm = p;  // p with the voxel's material's constants
  const auto nb = core::brick_counts(g);
  for (int bz = r.lo[2]; bz < r.hi[2]; ++bz)
    for (int by = r.lo[1]; by < r.hi[1]; ++by)
      for (int bx = r.lo[0]; bx < r.hi[0]; ++bx) {
        const std::uint32_t id = std::uint32_t((std::size_t(bz) * std::size_t(nb[1]) + std::size_t(by)) *
                                                   std::size_t(nb[0]) + std::size_t(bx));
        const BrickBox box = brick_box(g, id);
        bool changed = false;
        for (int z = box.lo[2]; z < box.hi[2]; ++z)
          for (int y = box.lo[1]; y < box.hi[1]; ++y)
            for (int x = box.lo[0]; x < box.hi[0]; ++x) {
              float w = 0;
              if (!weight(p, x, y, z, w)) continue;
              const std::size_t at = g.index(x, y, z);
              float& v = vol.voxels[at];
              const gpu::BrushPush* q = &p;
              if (cut) {
                const std::uint8_t mat = cut->ids[at];
                if (cc.critical[mat]) continue;  // a critical structure is never changed
              }
              if (per_material) {
                const std::uint8_t mat = cut->ids[at];
                pm.amount = cc.amount[mat];
                pm.inv_dens_scale = cc.inv_dens[mat];
                q = &pm;
              }
              const float nv = new_value(*q, g, pre, x, y, z, v, w);
              if (std::bit_cast<std::uint32_t>(nv) != std::bit_cast<std::uint32_t>(v)) changed = true;
              v = nv;
            }
        if (changed) res.dirty.push_back(id);
      }
  res.wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace isotouch::session
