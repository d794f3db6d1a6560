// brick_field.h - the sparse (bricked) published snapshot.
// Part of isotouch::core, header-only. The storage (BrickStore, the compact sample
// formats and their decoders) is in sample_field.h, the reads in field_view.h; this file
// builds a bricked SampleField (make_bricked_field, bricked_input_from_dense), encodes the
// compact formats and counts bytes (snapshot_bytes).
//
// Layout
// - The grid is cut into bricks of kBrickSize^3 voxels (OpenVDB's leaf size), brick
//   (bx, by, bz) holding voxels [8 bx, 8 bx + 8) x ... ; bricks counted ceil(dims / 8) per
//   axis, linear brick id = (bz * nby + by) * nbx + bx (x fastest).
// - An *active* brick (its value range, widened by the 1-voxel halo the gradient and the
//   trilinear cell need, straddles the isovalue) stores kBrickStored^3 = 9^3 samples: the
//   brick plus one voxel on the high side of every axis, so every trilinear cell whose
//   lower corner lies in the brick is read from that one brick (one table lookup per cell).
//   Local sample (i, j, k), i, j, k in 0..8, is voxel (8 bx + i, 8 by + j, 8 bz + k), local
//   order x fastest: i + 9 j + 81 k. Positions beyond the grid are never read (fill them
//   with the background value and a zero gradient).
// - Every other brick is *uniform*: entirely inside or entirely outside the isosurface. It
//   stores no samples, only its tile value (see tile_value()): every voxel in it reads
//   {tile, 0, 0, 0}. A cell belongs to the brick of its lower corner, so every cell of a
//   uniform brick reads the tile at its 8 corners.
// - Storage (BrickStore): table entry = pool index of an active brick's first sample,
//   slot * 729 (slots in ascending brick id), or BrickStore::kUniform | index into `tiles`
//   (uniform bricks in ascending brick id). Bytes: 4 per brick (table) + 16 per uniform brick (tile Sample) + 729 *
//   (16 | 8) per active brick (pool, fp32 | compact) + 32 per active brick (kUnorm16 decode
//   parameters); the fixed header (grid, format, fp16 scale) is not counted.
//
// Compact formats (item 5), 8 bytes per sample, decoded to float in FieldView:
// - kFp16: value as IEEE binary16 (round to nearest even); gradient per voxel step,
//   gradient[a] * spacing_m[a], as binary16 (1000 HU/mm = 1e6 HU/m overflows binary16,
//   1000 HU per 1 mm voxel does not), decoded as half * (1 / spacing) in float.
//   Worst-case error, |v| <= 65504 (beyond: saturated to +-65504, no bound):
//     value:    |v' - v| <= 2^-11 |v| + 2^-25
//     gradient: |g' - g| <= (2^-11 + 2^-22) |g| + 2^-24 / s      (s = spacing_m[a])
//   (binary16 keeps 11 significant bits: half an ulp is <= 2^-11 |x|, 2^-25 for subnormals;
//   the float decode adds two roundings of 2^-24).
// - kUnorm16: per active brick and channel c (value, gx, gy, gz): lo, hi = range of the
//   finite stored samples inside the grid; scale = (hi - lo) / 65534 rounded up to float;
//   q = round((x - lo) / scale) in 0..65534; 65535 = NaN (non-finite samples, the apron
//   beyond the grid). Decoded as lo + q * scale in float. Worst-case error:
//     |x' - x| <= scale / 2 + 2^-22 max(|lo|, |hi|)
//   (quantisation half a step, plus the float multiply and add, 2^-24 each on values up
//   to 2 max(|lo|, |hi|) and max(|lo|, |hi|)).
// Uniform bricks keep their fp32 tile in every format: their side of the surface is exact.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/core/grid.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/sample_field.h"

namespace isotouch::core {

// kBrickSize, kBrickStored, kBrickSamples, SampleFormat, CompactSample, BrickDecode and
// BrickStore live in sample_field.h (the published format).

/// Bricks per axis of `g`: ceil(dims / 8).
inline std::array<int, 3> brick_counts(const Grid& g) {
  return {(g.dims[0] + kBrickSize - 1) / kBrickSize, (g.dims[1] + kBrickSize - 1) / kBrickSize,
          (g.dims[2] + kBrickSize - 1) / kBrickSize};
}

/// The tile value of a brick whose (halo-widened) value range [lo, hi] does not straddle
/// `iso`: the bound of the range nearest tau (kAbove: lo if lo > tau (inside), hi if
/// hi <= tau (outside); kBelow mirrored), so the brick reads as the same side of the
/// surface as all its voxels. Returns false if the range straddles (the brick is active).
/// A range with no finite value (lo > hi: only NaN voxels) is uniform outside with tile
/// = NaN... callers pass `background` for it.
inline bool tile_value(float lo, float hi, const Isosurface& iso, float background, float& tile) {
  if (lo > hi) {
    tile = background;
    return true;
  }
  const double t = iso.tau;
  if (iso.inside == InsideIs::kAbove) {
    if (lo > t) { tile = lo; return true; }
    if (hi <= t) { tile = hi; return true; }
  } else {
    if (hi < t) { tile = hi; return true; }
    if (lo >= t) { tile = lo; return true; }
  }
  return false;
}

/// Where a published field's fp32 pool buffer goes once nothing needs it any more, instead
/// of back to the system: an engine that publishes again and again (a chain run per
/// isovalue, a benchmark) takes the buffer for its next pool, whose pages are then already
/// resident (a fresh pool of tens of MB is a page fault and a page of zeroes per 4 KiB or
/// 2 MiB written). give_back runs on whichever thread drops the last reference to the
/// store (servo::TripleBuffer: the publisher's), never while anything reads the buffer.
struct PoolSink {
  virtual ~PoolSink() = default;
  /// Takes `pool` (its contents are dead; its capacity is what counts). Must not throw.
  virtual void give_back(SamplePool&& pool) noexcept = 0;
};

/// What an engine (GPU sparse chain, CPU reference, or dense-to-bricks conversion) hands
/// over to be published as a bricked SampleField: the active bricks' fp32 samples and the
/// uniform bricks' tile values.
struct BrickedInput {
  Grid grid;
  float background = 0.0f;                  ///< value outside the grid (SampleField::background)
  std::vector<std::uint32_t> active;        ///< linear ids of active bricks, ascending
  SamplePool pool;                          ///< active.size() * kBrickSamples fp32 samples (resize() leaves them unwritten)
  std::vector<float> tile;                  ///< one per brick (all bricks); ignored for active ones
  /// Optional: receives `pool`'s buffer when the published store is destroyed (fp32), or
  /// once it is encoded (compact formats). Held weakly by the store: a sink destroyed first
  /// leaves the buffer to be freed.
  std::shared_ptr<PoolSink> recycle;
};

/// Stored samples of brick `b` (per-axis brick index) that lie inside the grid, per axis:
/// min(9, dims - 8 b) (the apron beyond the grid is never read).
inline std::array<int, 3> stored_in_grid(const Grid& g, const std::array<int, 3>& b) {
  std::array<int, 3> n{};
  for (int a = 0; a < 3; ++a) n[std::size_t(a)] = std::min(kBrickStored, g.dims[std::size_t(a)] - kBrickSize * b[std::size_t(a)]);
  return n;
}

/// Per-axis brick index of linear brick id `id` with `nb` bricks per axis.
inline std::array<int, 3> brick_coords(std::size_t id, const std::array<int, 3>& nb) {
  const std::size_t nx = std::size_t(nb[0]), ny = std::size_t(nb[1]);
  return {int(id % nx), int(id / nx % ny), int(id / (nx * ny))};
}

/// Copies the voxels of brick `id` (its 8^3 box clipped to the grid) from `from` to `to`,
/// two volumes of grid `g` (g.voxel_count() floats each, x fastest, index frame), row by
/// row. Sizes are not checked.
inline void copy_brick_voxels(const Grid& g, std::size_t id, const float* from, float* to) {
  const auto b = brick_coords(id, brick_counts(g));
  const int nx = g.dims[0], ny = g.dims[1];
  const int x0 = kBrickSize * b[0], n = std::min(x0 + kBrickSize, nx) - x0;
  const int y1 = std::min(kBrickSize * b[1] + kBrickSize, ny), z1 = std::min(kBrickSize * b[2] + kBrickSize, g.dims[2]);
  for (int z = kBrickSize * b[2]; z < z1; ++z)
    for (int y = kBrickSize * b[1]; y < y1; ++y) {
      const std::size_t row = (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(nx) + std::size_t(x0);
      std::memcpy(to + row, from + row, std::size_t(n) * sizeof(float));
    }
}

/// IEEE binary16 nearest to `x` (round to nearest, ties to even). Finite values beyond
/// +-65504 saturate to +-65504 (not Inf); +-Inf and NaN are kept. Encoder only (not the
/// servo path).
inline std::uint16_t float_to_half(double x) {
  if (std::isnan(x)) return 0x7e00u;
  const std::uint16_t sign = std::signbit(x) ? 0x8000u : 0u;
  const double a = std::fabs(x);
  if (std::isinf(a)) return std::uint16_t(sign | 0x7c00u);
  if (a >= 65504.0) return std::uint16_t(sign | 0x7bffu);
  if (a < 0x1p-14) return std::uint16_t(sign | std::uint16_t(std::nearbyint(a * 0x1p24)));  // subnormal (or 2^-14)
  int e = 0;
  std::frexp(a, &e);                                     // a in [2^(e-1), 2^e)
  const double m = std::nearbyint(std::ldexp(a, 11 - e));  // 11 significant bits, 1024..2048
  // m = 2048 carries into the exponent, which is what the bit pattern needs.
  return std::uint16_t(sign | ((std::uint32_t(e - 1 + 15) << 10) + (std::uint32_t(m) - 1024u)));
}

namespace detail {

[[noreturn]] inline void bad_bricked_input(const std::string& what) {
  throw std::invalid_argument("make_bricked_field: " + what);
}

/// Check `in` against the contract; throws std::invalid_argument naming the field.
inline void validate(const BrickedInput& in) {
  if (in.grid.empty())
    bad_bricked_input("BrickedInput.grid: empty dims " + std::to_string(in.grid.dims[0]) + "x" +
                      std::to_string(in.grid.dims[1]) + "x" + std::to_string(in.grid.dims[2]));
  const auto nb = brick_counts(in.grid);
  const std::size_t total = std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]);
  if (in.tile.size() != total)
    bad_bricked_input("BrickedInput.tile: " + std::to_string(in.tile.size()) + " values, " + std::to_string(total) +
                      " bricks");
  if (in.pool.size() != in.active.size() * std::size_t(kBrickSamples))
    bad_bricked_input("BrickedInput.pool: " + std::to_string(in.pool.size()) + " samples, " +
                      std::to_string(in.active.size()) + " active bricks need " +
                      std::to_string(in.active.size() * std::size_t(kBrickSamples)));
  if (in.active.size() > BrickStore::kMaxSlots)
    bad_bricked_input("BrickedInput.active: " + std::to_string(in.active.size()) + " active bricks, at most " +
                      std::to_string(BrickStore::kMaxSlots));
  for (std::size_t i = 0; i < in.active.size(); ++i)
    if (in.active[i] >= total || (i > 0 && in.active[i] <= in.active[i - 1]))
      bad_bricked_input("BrickedInput.active[" + std::to_string(i) + "] = " + std::to_string(in.active[i]) +
                        ": not ascending or not below " + std::to_string(total) + " bricks");
}

/// kUnorm16 parameters of one channel from its finite range [lo, hi] (lo > hi: none).
inline void unorm16_params(double lo, double hi, float& offset, float& scale) {
  if (!(lo <= hi)) {
    offset = 0.f;
    scale = 0.f;
    return;
  }
  offset = float(lo);  // lo is a float value: exact
  const double range = hi - lo;
  scale = float(range / double(kUnormMax));
  if (double(scale) * double(kUnormMax) < range) scale = std::nextafter(scale, std::numeric_limits<float>::infinity());
}

inline std::uint16_t unorm16_encode(float x, float offset, float scale) {
  if (!std::isfinite(x)) return kUnormNaN;
  if (scale == 0.f) return 0;
  const double q = std::nearbyint((double(x) - double(offset)) / double(scale));
  return std::uint16_t(std::clamp(q, 0.0, double(kUnormMax)));
}

/// The 729 compact samples (kFp16 or kUnorm16) of active brick `b` (per-axis brick index)
/// of `grid` from its fp32 samples `src`; `d` gets its kUnorm16 decode parameters (unused
/// for kFp16). Samples beyond the grid get the NaN code. One brick of encode_compact (the
/// live field, session/live_field.h, encodes the bricks an edit changed with it).
inline void encode_brick(const Grid& grid, const std::array<int, 3>& b, const Sample* src, SampleFormat f,
                         CompactSample* dst, BrickDecode& d) {
  const auto n = stored_in_grid(grid, b);
  const double sp[3] = {grid.spacing_m.x, grid.spacing_m.y, grid.spacing_m.z};
  auto in_grid = [&](int l) {
    return l % kBrickStored < n[0] && l / kBrickStored % kBrickStored < n[1] && l / (kBrickStored * kBrickStored) < n[2];
  };
  if (f == SampleFormat::kFp16) {
    for (int l = 0; l < kBrickSamples; ++l) {
      const Sample& s = src[l];
      dst[l] = in_grid(l) ? CompactSample{float_to_half(s.value),
                                          {float_to_half(double(s.gx) * sp[0]), float_to_half(double(s.gy) * sp[1]),
                                           float_to_half(double(s.gz) * sp[2])}}
                          : CompactSample{0x7e00u, {0, 0, 0}};
    }
    return;
  }
  for (int c = 0; c < 4; ++c) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int l = 0; l < kBrickSamples; ++l) {
      const float x = (&src[l].value)[c];
      if (!in_grid(l) || !std::isfinite(x)) continue;
      lo = std::min(lo, double(x));
      hi = std::max(hi, double(x));
    }
    unorm16_params(lo, hi, d.offset[c], d.scale[c]);
  }
  for (int l = 0; l < kBrickSamples; ++l) {
    const Sample& s = src[l];
    dst[l] = in_grid(l) ? CompactSample{unorm16_encode(s.value, d.offset[0], d.scale[0]),
                                        {unorm16_encode(s.gx, d.offset[1], d.scale[1]),
                                         unorm16_encode(s.gy, d.offset[2], d.scale[2]),
                                         unorm16_encode(s.gz, d.offset[3], d.scale[3])}}
                        : CompactSample{kUnormNaN, {kUnormNaN, kUnormNaN, kUnormNaN}};
  }
}

/// The compact pool (kFp16 or kUnorm16) of `pool`; `decode` gets one entry per slot (kUnorm16).
inline std::vector<CompactSample> encode_compact(const BrickedInput& in, SampleFormat f,
                                                 std::vector<BrickDecode>& decode) {
  std::vector<CompactSample> out(in.pool.size());
  const auto nb = brick_counts(in.grid);
  if (f == SampleFormat::kUnorm16) decode.resize(in.active.size());
  BrickDecode unused{};
  for (std::size_t slot = 0; slot < in.active.size(); ++slot)
    encode_brick(in.grid, brick_coords(in.active[slot], nb), in.pool.data() + slot * kBrickSamples, f,
                 out.data() + slot * kBrickSamples, f == SampleFormat::kUnorm16 ? decode[slot] : unused);
  return out;
}

/// Empty if a stored value `v` can be kept in format `f` without moving it across an
/// isovalue, else why not: fp16 saturates beyond +-65504, unorm16 has no code for +-Inf
/// (fp32 keeps everything).
inline std::string compact_refusal(float v, SampleFormat f) {
  if (f == SampleFormat::kFp16 && std::isfinite(v) && std::fabs(v) > 65504.0f) return " (|v| > 65504)";
  if (f == SampleFormat::kUnorm16 && std::isinf(v)) return " (no code for Inf)";
  return {};
}

/// The store's shared pool: with a sink, a deleter that hands the buffer to it (if it is
/// still alive) instead of freeing it.
inline std::shared_ptr<const SamplePool> share_pool(SamplePool&& pool, const std::shared_ptr<PoolSink>& sink) {
  if (!sink) return std::make_shared<const SamplePool>(std::move(pool));
  struct GiveBack {
    std::weak_ptr<PoolSink> sink;
    void operator()(const SamplePool* p) const noexcept {
      if (const std::shared_ptr<PoolSink> s = sink.lock()) s->give_back(std::move(*const_cast<SamplePool*>(p)));
      delete p;
    }
  };
  // (If the control block cannot be allocated, shared_ptr calls the deleter: no leak.)
  return std::shared_ptr<const SamplePool>(new SamplePool(std::move(pool)), GiveBack{sink});
}

}  // namespace detail

/// Publish `in` as a bricked SampleField in format `f`: grid and background from `in`,
/// version 0, dense `samples` empty, `bricks` the immutable BrickStore (table, tiles, pool;
/// fp32 moves `in.pool` into the store, compact formats encode it, see the file comment).
/// The apron beyond the grid is reset to {background, 0, 0, 0} (fp32) or NaN (compact);
/// it is never read. @throws std::invalid_argument naming the BrickedInput field that
/// breaks the contract (tile count, pool size, active ids).
inline SampleField make_bricked_field(BrickedInput in, SampleFormat f) {
  detail::validate(in);
  // Compact formats must not move a stored value to the other side of any isovalue:
  // fp16 saturates beyond +-65504 and unorm16 has no code for +-Inf. Refuse such input
  // (fp32 stores it exactly) instead of publishing a field that reads differently.
  if (f != SampleFormat::kFp32)
    for (std::size_t i = 0; i < in.pool.size(); ++i) {
      const float v = in.pool[i].value;
      if (const std::string why = detail::compact_refusal(v, f); !why.empty())
        throw std::invalid_argument("make_bricked_field: BrickedInput.pool[" + std::to_string(i) + "].value = " +
                                    std::to_string(v) + " cannot be stored as " + to_string(f) + why +
                                    "; use fp32 samples");
    }
  auto store = std::make_shared<BrickStore>();
  store->bricks = brick_counts(in.grid);
  store->format = f;
  const std::size_t total = in.tile.size();
  store->table.resize(total);
  store->tiles.reserve(total - in.active.size());
  for (std::size_t id = 0, slot = 0; id < total; ++id) {
    if (slot < in.active.size() && in.active[slot] == id) {
      store->table[id] = std::uint32_t(slot++ * kBrickSamples);
    } else {
      store->table[id] = BrickStore::kUniform | std::uint32_t(store->tiles.size());
      store->tiles.push_back({in.tile[id], 0.f, 0.f, 0.f});
    }
  }
  // The apron beyond the grid: the contract's fill, whatever the engine wrote there.
  for (std::size_t slot = 0; slot < in.active.size(); ++slot) {
    const auto n = stored_in_grid(in.grid, brick_coords(in.active[slot], store->bricks));
    if (n[0] == kBrickStored && n[1] == kBrickStored && n[2] == kBrickStored) continue;
    Sample* s = in.pool.data() + slot * kBrickSamples;
    for (int k = 0; k < kBrickStored; ++k)
      for (int j = 0; j < kBrickStored; ++j)
        for (int i = 0; i < kBrickStored; ++i)
          if (i >= n[0] || j >= n[1] || k >= n[2]) s[i + kBrickStored * (j + kBrickStored * k)] = {in.background, 0, 0, 0};
  }
  if (f == SampleFormat::kFp32) {
    store->pool = detail::share_pool(std::move(in.pool), in.recycle);
  } else {
    store->compact = std::make_shared<const std::vector<CompactSample>>(detail::encode_compact(in, f, store->decode));
    store->fp16_unscale = {float(1.0 / in.grid.spacing_m.x), float(1.0 / in.grid.spacing_m.y),
                           float(1.0 / in.grid.spacing_m.z)};
    if (in.recycle) in.recycle->give_back(std::move(in.pool));
  }
  if (!store->seal(in.grid.dims)) detail::bad_bricked_input("the built store does not seal (internal error)");
  SampleField out;
  out.grid = in.grid;
  out.background = in.background;
  out.version = 0;
  out.bricks = std::move(store);
  return out;
}

/// The CPU conversion of a dense field to bricks (tests, scenes comparing dense and
/// bricked, the reference the GPU sparse chain is checked against): per brick the value
/// range over its voxels widened by 1 voxel on every side (clipped to the grid; NaN
/// skipped, like engine brick_minmax with halo 1), tile_value() decides; an active brick
/// copies its 9^3 samples (beyond the grid: {background, 0, 0, 0}). One departure from
/// brick_minmax: a brick whose widened range holds a NaN voxel (outside every isosurface)
/// and whose finite values are inside is active, so it keeps reading NaN where dense does.
/// Background from `dense`. @throws std::invalid_argument if `dense` is not a dense field
/// with one sample per voxel.
inline BrickedInput bricked_input_from_dense(const SampleField& dense, const Isosurface& iso) {
  const Grid& g = dense.grid;
  if (dense.bricks || g.empty() || dense.samples.size() != g.voxel_count())
    throw std::invalid_argument("bricked_input_from_dense: SampleField.samples has " +
                                std::to_string(dense.samples.size()) + " samples for " +
                                std::to_string(g.voxel_count()) + " voxels" + (dense.bricks ? " (bricked field)" : ""));
  BrickedInput in;
  in.grid = g;
  in.background = dense.background;
  const auto nb = brick_counts(g);
  const std::size_t total = std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]);
  in.tile.assign(total, 0.f);
  for (std::size_t id = 0; id < total; ++id) {
    const auto b = brick_coords(id, nb);
    int lo_i[3], hi_i[3];
    for (int a = 0; a < 3; ++a) {
      lo_i[a] = std::max(kBrickSize * b[std::size_t(a)] - 1, 0);
      hi_i[a] = std::min(kBrickSize * b[std::size_t(a)] + kBrickSize + 1, g.dims[std::size_t(a)]);
    }
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    bool nan = false;
    for (int z = lo_i[2]; z < hi_i[2]; ++z)
      for (int y = lo_i[1]; y < hi_i[1]; ++y)
        for (int x = lo_i[0]; x < hi_i[0]; ++x) {
          const float v = dense.samples[g.index(x, y, z)].value;
          if (v != v) {
            nan = true;
            continue;
          }
          lo = v < lo ? v : lo;
          hi = v > hi ? v : hi;
        }
    float tile = 0.f;
    const bool uniform = tile_value(lo, hi, iso, dense.background, tile) && !(nan && lo <= hi && iso.contains(tile));
    if (uniform) {
      in.tile[id] = tile;
      continue;
    }
    in.active.push_back(std::uint32_t(id));
    const std::size_t base = in.pool.size();
    in.pool.resize(base + kBrickSamples, Sample{dense.background, 0.f, 0.f, 0.f});
    const auto n = stored_in_grid(g, b);
    for (int k = 0; k < n[2]; ++k)
      for (int j = 0; j < n[1]; ++j)
        for (int i = 0; i < n[0]; ++i)
          in.pool[base + std::size_t(i + kBrickStored * (j + kBrickStored * k))] =
              dense.samples[g.index(kBrickSize * b[0] + i, kBrickSize * b[1] + j, kBrickSize * b[2] + k)];
  }
  return in;
}

/// Bytes of the dense fp32 snapshot of `g`: voxels * 16.
inline std::uint64_t dense_fp32_bytes(const Grid& g) { return std::uint64_t(g.voxel_count()) * sizeof(Sample); }

/// Bytes of a published snapshot: dense, voxels * 16; bricked, table (4 per brick) + tiles
/// (16 per uniform brick) + pool (729 * 16 or 8 per active brick) + kUnorm16 decode
/// parameters (32 per active brick). The fixed header (grid, format) is not counted.
inline std::uint64_t snapshot_bytes(const SampleField& f) {
  if (!f.bricks) return dense_fp32_bytes(f.grid);
  const BrickStore& b = *f.bricks;
  const std::uint64_t per_sample = b.format == SampleFormat::kFp32 ? sizeof(Sample) : sizeof(CompactSample);
  return std::uint64_t(b.table.size()) * sizeof(std::uint32_t) + std::uint64_t(b.tiles.size()) * sizeof(Sample) +
         std::uint64_t(b.active_bricks()) * kBrickSamples * per_sample +
         (b.format == SampleFormat::kUnorm16 ? std::uint64_t(b.active_bricks()) * sizeof(BrickDecode) : 0);
}

/// Brick counts of a published snapshot: all bricks and the active ones (stored with
/// samples). A dense field counts its grid's bricks, all active.
struct BrickUsage {
  std::size_t total = 0;
  std::size_t active = 0;
};
inline BrickUsage brick_usage(const SampleField& f) {
  if (f.bricks) return {f.bricks->total_bricks(), f.bricks->active_bricks()};
  const auto nb = brick_counts(f.grid);
  const std::size_t n = f.grid.empty() ? 0 : std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]);
  return {n, n};
}

}  // namespace isotouch::core
