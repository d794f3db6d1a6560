// raycast_field.cpp - the field the ray caster marches (engine/raycast.h, RaycastField): the
// voxels, the bricks' value ranges widened at the grid's faces, and each cell's distance to the
// nearest active cell (empty-space skipping).
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/engine/raycast.h"
#include "isotouch/engine/raycast_detail.h"

namespace isotouch::engine {

namespace {

void widen_faces(RaycastField& f) {
  if (!(f.background == f.background)) return;  // NaN: outside everything, no widening needed
  const auto& b = f.bricks;
  for (int z = 0; z < b[2]; ++z)
    for (int y = 0; y < b[1]; ++y)
      for (int x = 0; x < b[0]; ++x) {
        if (!(x == 0 || y == 0 || z == 0 || x == b[0] - 1 || y == b[1] - 1 || z == b[2] - 1)) continue;
        const std::size_t i = (std::size_t(z) * std::size_t(b[1]) + std::size_t(y)) * std::size_t(b[0]) + std::size_t(x);
        f.brick_minmax[2 * i] = std::min(f.brick_minmax[2 * i], f.background);
        f.brick_minmax[2 * i + 1] = std::max(f.brick_minmax[2 * i + 1], f.background);
      }
}

/// A 3-D bit set, x fastest, 64 bits per word, rows padded to whole words.
struct Bits3 {
  int nx = 0, ny = 0, nz = 0, words = 0;  ///< bits per axis, words per row
  std::vector<std::uint64_t> w;
  Bits3(int x, int y, int z)
      : nx(x), ny(y), nz(z), words((x + 63) / 64), w(std::size_t(words) * std::size_t(y) * std::size_t(z), 0) {}
  std::uint64_t* row(int y, int z) { return w.data() + (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(words); }
  const std::uint64_t* row(int y, int z) const {
    return w.data() + (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(words);
  }
  void set(int x, int y, int z) { row(y, z)[x >> 6] |= std::uint64_t(1) << (x & 63); }
  std::size_t plane_words() const { return std::size_t(ny) * std::size_t(words); }
  /// Clears every bit with x >= ex, y >= ey or z >= ez (and the row padding). One flat pass
  /// per plane against that plane's mask (vectorized; rows are only a few words wide).
  void keep(int ex, int ey, int ez) {
    const std::size_t P = plane_words();
    std::vector<std::uint64_t> mask(P, 0);
    for (int y = 0; y < std::min(ey, ny); ++y)
      for (int i = 0; i < words; ++i) {
        const int first = 64 * i;
        mask[std::size_t(y) * std::size_t(words) + std::size_t(i)] =
            first >= ex ? 0 : ex - first >= 64 ? ~std::uint64_t(0) : (std::uint64_t(1) << (ex - first)) - 1;
      }
    for (int z = 0; z < nz; ++z) {
      std::uint64_t* r = w.data() + std::size_t(z) * P;
      if (z >= ez) {
        std::fill(r, r + P, 0);
        continue;
      }
      for (std::size_t k = 0; k < P; ++k) r[k] &= mask[k];
    }
  }
};

/// out = in dilated by the box [lo, 1]^3 (lo = 0: out(x) = OR of in(x .. x + 1) per axis,
/// lo = -1: the 3^3 cube). Bits past the set's extent read 0. All three sets have the same
/// extent; tmp is scratch. The x pass runs over the whole array as one bit string: across a
/// row's end a shift carries a bit only into the row's last bit (x >= nx - 1, or its
/// padding), which the caller's keep() with ex < nx clears, and with lo = -1 also out of
/// it, zero in a set so kept. The y and z passes OR whole planes and the whole set at a
/// row's and a plane's offset: flat loops the compiler vectorizes, where per-row loops of a
/// few words did not (rows of an edit's box are 3 words wide).
void dilate(const Bits3& in, Bits3& out, int lo, Bits3& tmp) {
  const std::size_t N = in.w.size(), W = std::size_t(in.words), P = in.plane_words();
  const std::uint64_t* r = in.w.data();
  std::uint64_t* t = tmp.w.data();
  // x: shifting right by 1 brings bit x + 1 down to x (and left by 1, x - 1 up to x).
  for (std::size_t k = 0; k < N; ++k) {
    const std::uint64_t next = k + 1 < N ? r[k + 1] : 0;
    t[k] = r[k] | (r[k] >> 1) | (next << 63);
  }
  if (lo < 0)
    for (std::size_t k = 0; k < N; ++k) {
      const std::uint64_t prev = k > 0 ? r[k - 1] : 0;
      t[k] |= (r[k] << 1) | (prev >> 63);
    }
  // y: OR of the rows y + lo .. y + 1, within each plane.
  std::uint64_t* o = out.w.data();
  std::copy(t, t + N, o);
  for (std::size_t z0 = 0; z0 < N; z0 += P) {
    for (std::size_t k = z0; k + W < z0 + P; ++k) o[k] |= t[k + W];
    if (lo < 0)
      for (std::size_t k = z0 + W; k < z0 + P; ++k) o[k] |= t[k - W];
  }
  // z: OR of the planes z + lo .. z + 1.
  std::copy(o, o + N, t);
  for (std::size_t k = 0; k + P < N; ++k) t[k] |= o[k + P];
  if (lo < 0)
    for (std::size_t k = P; k < N; ++k) t[k] |= o[k - P];
  std::swap(out.w, tmp.w);
}
}  // namespace

namespace raycast_detail {

double value_magnitude(const std::vector<float>& values, float background) {
  double mag = 0;
  if (std::isfinite(background)) mag = std::max(mag, std::fabs(double(background)));
  for (float v : values)
    if (std::isfinite(v)) mag = std::max(mag, std::fabs(double(v)));
  return mag;
}

std::vector<std::uint8_t> cell_distances_with(const core::Grid& grid, const std::vector<float>& values,
                                              const core::Isosurface& iso, float background, double mag) {
  const auto& n = grid.dims;
  const double sign = iso.inside == core::InsideIs::kAbove ? 1.0 : -1.0;
  const double tau = double(float(iso.tau));  // the shader's isovalue (make_params)
  const double margin = 1e-5 * (mag + std::fabs(tau));
  // hot: sign (v - tau) >= -margin, as a float comparison with the bound rounded outward
  // (a few more hot voxels at most); NaN compares false.
  const bool above = sign > 0;
  const float lim = above ? std::nextafter(float(tau - margin), -std::numeric_limits<float>::infinity())
                          : std::nextafter(float(tau + margin), std::numeric_limits<float>::infinity());
  auto hot = [above, lim](float v) { return above ? v >= lim : v <= lim; };
  // Hot voxels at index [-1, n + 1] per axis (stored at + 1), the background outside the grid.
  Bits3 h(n[0] + 3, n[1] + 3, n[2] + 3);
  const bool bg_hot = hot(background);
  // A row's flags as bytes, flags[x + 1] for voxel x (a compare loop the compiler
  // vectorizes), then 8 bytes of 0/1 at a time into 8 bits: the multiply gathers byte j's
  // bit into bit 56 + j (no carries: each partial product lands on its own bit). Bytes past
  // the row's voxels stay 0 (a row's padding stays clear). Little-endian loads.
  static_assert(std::endian::native == std::endian::little, "cell distances pack bytes little-endian");
  std::vector<std::uint8_t> flags(std::size_t(h.words) * 64, 0);
  for (int z = 0; z < h.nz; ++z)
    for (int y = 0; y < h.ny; ++y) {
      const bool in_plane = z >= 1 && z <= n[2] && y >= 1 && y <= n[1];
      if (!in_plane) {
        if (bg_hot)
          for (int x = 0; x < h.nx; ++x) h.set(x, y, z);
        continue;
      }
      const float* r = values.data() + (std::size_t(z - 1) * std::size_t(n[1]) + std::size_t(y - 1)) * std::size_t(n[0]);
      if (bg_hot) {
        h.set(0, y, z);
        h.set(n[0] + 1, y, z);
        h.set(n[0] + 2, y, z);
      }
      std::uint8_t* fl = flags.data() + 1;
      for (int x = 0; x < n[0]; ++x) fl[x] = hot(r[x]) ? 1 : 0;
      std::uint64_t* hw = h.row(y, z);
      for (int i = 0; i < h.words; ++i) {
        std::uint64_t word = 0;
        for (int b8 = 0; b8 < 8; ++b8) {
          std::uint64_t v;
          std::memcpy(&v, flags.data() + 64 * i + 8 * b8, 8);
          word |= ((v * 0x0102040810204080ull) >> 56) << (8 * b8);
        }
        hw[i] |= word;
      }
    }
  // Active cells: cell c (stored s = c + 1) has corners at stored voxels s .. s + 1. All
  // sets share h's extent (n + 3 per axis); cells use the first n + 2, the rest stays 0.
  const int ex = n[0] + 2, ey = n[1] + 2, ez = n[2] + 2;
  Bits3 cur(h.nx, h.ny, h.nz), prev(h.nx, h.ny, h.nz), tmp(h.nx, h.ny, h.nz);
  dilate(h, cur, 0, tmp);
  cur.keep(ex, ey, ez);
  const std::size_t cx = std::size_t(ex), cy = std::size_t(ey);
  // (8 bytes of slack: the level loop writes 8 bytes at a time, merged, up to 7 past the last cell)
  std::vector<std::uint8_t> dist(cx * cy * std::size_t(ez) + 8, std::uint8_t(ISOTOUCH_RAYCAST_DIST_MAX));
  // kSpread[b]: byte j is 0xff where bit j of b is set (a level's new cells 8 at a time).
  static const std::array<std::uint64_t, 256> kSpread = [] {
    std::array<std::uint64_t, 256> t{};
    for (unsigned b = 0; b < 256; ++b)
      for (unsigned j = 0; j < 8; ++j)
        if (b >> j & 1u) t[b] |= std::uint64_t(0xff) << (8 * j);
    return t;
  }();
  // Level r: the cells the r-th dilation by the 3^3 cube newly covers are at distance r.
  const std::size_t W = std::size_t(cur.words), rows = std::size_t(cur.ny);
  for (unsigned r = 0; r < ISOTOUCH_RAYCAST_DIST_MAX; ++r) {
    bool any_new = false;
    const std::uint64_t* c = cur.w.data();
    const std::uint64_t* p = prev.w.data();  // level r - 1 (all 0 before level 0)
    for (std::size_t k = 0; k < cur.w.size(); ++k) {
      std::uint64_t fresh = c[k] & ~p[k];  // (kept: none at y >= ey, z >= ez, x >= ex)
      if (!fresh) continue;
      any_new = true;
      const std::size_t row = k / W, i = k % W, y = row % rows, z = row / rows;
      std::uint8_t* out = dist.data() + (z * cy + y) * cx + 64 * i;
      const std::uint64_t level = 0x0101010101010101ull * r;
      for (int b8 = 0; b8 < 8; ++b8) {
        const unsigned byte = unsigned(fresh >> (8 * b8)) & 0xffu;
        if (byte == 0) continue;
        const std::uint64_t m = kSpread[byte];
        std::uint64_t v;
        std::memcpy(&v, out + 8 * b8, 8);
        v = (v & ~m) | (level & m);
        std::memcpy(out + 8 * b8, &v, 8);
      }
    }
    if (!any_new || r + 1 == ISOTOUCH_RAYCAST_DIST_MAX) break;  // all covered, or the cap
    std::swap(cur.w, prev.w);  // prev = level r
    dilate(prev, cur, -1, tmp);
    cur.keep(ex, ey, ez);  // cur = level r + 1
  }
  dist.resize(cx * cy * std::size_t(ez));
  return dist;
}

}  // namespace raycast_detail

using namespace raycast_detail;

std::vector<std::uint8_t> cell_distances(const core::Grid& grid, const std::vector<float>& values,
                                         const core::Isosurface& iso, float background) {
  if (grid.empty() || values.size() != grid.voxel_count())
    throw std::invalid_argument("raycast: cell distances: " + std::to_string(values.size()) +
                                " values for a grid of " + std::to_string(grid.voxel_count()) + " voxels");
  return cell_distances_with(grid, values, iso, background, value_magnitude(values, background));
}

RaycastField make_raycast_field(const core::Grid& grid, std::vector<float> values, core::Isosurface iso,
                                float background, const BrickRanges& r) {
  if (grid.empty() || values.size() != grid.voxel_count())
    throw std::invalid_argument("raycast: " + std::to_string(values.size()) + " values for a grid of " +
                                std::to_string(grid.voxel_count()) + " voxels");
  for (int a = 0; a < 3; ++a)
    if (r.bricks[a] != (grid.dims[a] + 7) / 8)
      throw std::invalid_argument("raycast: brick ranges for " + std::to_string(r.bricks[a]) + " bricks along axis " +
                                  std::to_string(a) + ", the grid needs " + std::to_string((grid.dims[a] + 7) / 8));
  if (r.halo != 1) throw std::invalid_argument("raycast: brick ranges need halo 1, got " + std::to_string(r.halo));
  RaycastField f;
  f.grid = grid;
  f.values = std::move(values);
  f.bricks = r.bricks;
  f.iso = iso;
  f.background = background;
  f.brick_minmax.resize(2 * r.count());
  for (std::size_t i = 0; i < r.count(); ++i) {
    f.brick_minmax[2 * i] = r.min[i];
    f.brick_minmax[2 * i + 1] = r.max[i];
  }
  widen_faces(f);
  f.cell_dist = cell_distances(grid, f.values, iso, background);
  return f;
}

RaycastField make_raycast_field(const core::Grid& grid, std::vector<float> values, core::Isosurface iso,
                                float background) {
  Volume v;
  v.grid = grid;
  v.voxels = std::move(values);
  const BrickRanges r = brick_minmax_cpu(v, 1);
  return make_raycast_field(grid, std::move(v.voxels), iso, background, r);
}
}  // namespace isotouch::engine
