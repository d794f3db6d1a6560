// sample_field.h - the plane-ready sample format the engine publishes and the servo reads,
// dense or bricked, and how to decode a stored sample.
// Part of isotouch::core (engine/ writes it, servo/ reads it through core::FieldView).
// Building a bricked field (the builders, the encoders, byte accounting) is brick_field.h.
#pragma once
#include <array>
#include <bit>
#include <cstdint>
#include <limits>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#include "isotouch/core/grid.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"

namespace isotouch::core {

/// One sample per voxel: the scalar value and its gradient.
/// Layout = GLSL `vec4(value, gx, gy, gz)` written by shaders/gradient.comp (16 bytes).
struct Sample {
  float value;  ///< scalar value (scanner units, HU, or signed distance [m])
  float gx;     ///< d value / dx [value units / m], grid-world frame
  float gy;     ///< d value / dy
  float gz;     ///< d value / dz
};
static_assert(sizeof(Sample) == 16, "Sample must match GLSL vec4");

/// std::allocator, except that an element made without a value is default-initialised
/// (a Sample: left unwritten) where std::allocator value-initialises it (zeroes). A pool
/// sized by resize(n) and then written whole by the engine is not zero-filled first: tens
/// of MB and one pass over memory, on one thread, before the threads that write it start.
/// Elements made from a value (resize(n, s), copies, push_back) are as with std::allocator.
template <class T>
struct DefaultInitAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = DefaultInitAllocator<U>;
  };
  DefaultInitAllocator() = default;
  template <class U>
  DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
  }
};
/// The fp32 samples of a brick pool (BrickStore::pool, BrickedInput::pool): resize(n)
/// leaves the new samples unwritten (DefaultInitAllocator); give a value to have them set.
using SamplePool = std::vector<Sample, DefaultInitAllocator<Sample>>;

// ---- Bricks (the layout is documented in brick_field.h) ---------------------------------
inline constexpr int kBrickSize = 8;                      ///< voxels per brick edge
inline constexpr int kBrickStored = kBrickSize + 1;       ///< stored samples per edge (+1 apron)
inline constexpr int kBrickSamples = kBrickStored * kBrickStored * kBrickStored;  ///< 729

/// How the samples of active bricks are stored.
enum class SampleFormat : std::uint8_t {
  kFp32,     ///< core::Sample, 16 B per sample
  kFp16,     ///< value + gradient as IEEE half, 8 B per sample (gradient scaled, see CompactSample)
  kUnorm16,  ///< per-brick normalized 16-bit integers, 8 B per sample (see BrickDecode)
};

/// "fp32" / "fp16" / "unorm16".
constexpr const char* to_string(SampleFormat f) {
  return f == SampleFormat::kFp32 ? "fp32" : (f == SampleFormat::kFp16 ? "fp16" : "unorm16");
}

/// A compact sample (8 bytes), meaning set by the brick store's format:
/// - kFp16: `value` = IEEE binary16 of the value; `g[a]` = binary16 of gradient[a] *
///   spacing_m[a], the gradient per voxel step [value units / voxel] (1000 HU/mm is 1e6 HU/m,
///   beyond binary16's 65504, but 1000 HU per 1 mm voxel). Decoded by half_to_float and a
///   multiply by 1/spacing (BrickStore::fp16_unscale).
/// - kUnorm16: q in 0..65534 -> offset + q * scale with the brick's BrickDecode per channel;
///   65535 is NaN (non-finite values and the apron beyond the grid).
struct CompactSample {
  std::uint16_t value;
  std::uint16_t g[3];
};
static_assert(sizeof(CompactSample) == 8, "compact samples are 8 bytes");

/// kUnorm16 decode parameters of one active brick, per channel (value, gx, gy, gz):
/// decoded = offset[c] + q * scale[c] (float arithmetic), q = 65535 -> NaN.
struct BrickDecode {
  float offset[4];
  float scale[4];
};
static_assert(sizeof(BrickDecode) == 32, "");

inline constexpr std::uint16_t kUnormNaN = 0xffff;  ///< the kUnorm16 NaN code
inline constexpr std::uint16_t kUnormMax = 0xfffe;  ///< largest kUnorm16 level (65534)

/// IEEE binary16 -> float, exact (subnormals, +-Inf and NaN included). No table, no branch
/// on the normal path: the 15 magnitude bits shifted into a float and scaled by 2^112.
inline float half_to_float(std::uint16_t h) {
  const std::uint32_t sign = std::uint32_t(h & 0x8000u) << 16;
  const std::uint32_t m = std::uint32_t(h & 0x7fffu) << 13;
  const float mag = m >= 0x0f800000u ? std::bit_cast<float>(m | 0x7f800000u)   // Inf / NaN
                                     : std::bit_cast<float>(m) * 0x1p112f;      // exact
  return std::bit_cast<float>(std::bit_cast<std::uint32_t>(mag) | sign);
}

/// kUnorm16 decode of one channel (see BrickDecode).
inline float unorm16_to_float(std::uint16_t q, float offset, float scale) {
  return q == kUnormNaN ? std::numeric_limits<float>::quiet_NaN() : offset + float(q) * scale;
}

/// The bricked snapshot (items 4 and 5): a brick table, a pool of active bricks and the
/// uniform bricks' tiles. Immutable once built (brick_field.h: make_bricked_field, which
/// seal()s it); shared through std::shared_ptr<const BrickStore>. The pool is itself held
/// by shared_ptr so that a later snapshot can reference it (unchanged bricks
/// shared between snapshots). Not copyable: seal() records pointers into this object.
struct BrickStore {
  /// What FieldView copies per tick: read pointers into the store, checked once by seal().
  struct Sealed {
    std::array<int, 3> dims{0, 0, 0};       ///< grid dims the table was checked against
    const std::uint32_t* table = nullptr;   ///< null: not sealed (FieldView reads nothing)
    const Sample* tiles = nullptr;
    const Sample* pool = nullptr;           ///< kFp32
    const CompactSample* compact = nullptr; ///< kFp16 / kUnorm16
    std::size_t nbx = 0, nbxy = 0;          ///< bricks along x; along x times along y
    const BrickDecode* decode = nullptr;    ///< kUnorm16: one per slot (`decode` or `shared_decode`)
    bool thin = false;                      ///< an axis of dims is 1 voxel long
  };

  BrickStore() = default;
  BrickStore(const BrickStore&) = delete;
  BrickStore& operator=(const BrickStore&) = delete;

  /// Table entry flag: the brick is uniform; the low 31 bits index `tiles`.
  static constexpr std::uint32_t kUniform = 0x80000000u;
  /// Most active bricks a store holds (slot * 729 below kUniform).
  static constexpr std::size_t kMaxSlots = (std::size_t(kUniform) - 1) / kBrickSamples;
  /// The slot of an active brick's table entry.
  static std::uint32_t slot_of(std::uint32_t entry) { return entry / std::uint32_t(kBrickSamples); }

  std::array<int, 3> bricks{0, 0, 0};     ///< bricks per axis, ceil(dims / 8)
  SampleFormat format = SampleFormat::kFp32;
  /// One entry per brick, linear id (bz * nby + by) * nbx + bx: for an active brick the
  /// pool index of its first sample, slot * kBrickSamples (slot = its rank among the active
  /// bricks, or in an arena store any slot below slot_capacity; stored premultiplied, which
  /// saves a multiply on the servo's dependent load chain), or kUniform | tile index for a
  /// uniform one. Hence at most kMaxSlots slots.
  std::vector<std::uint32_t> table;
  /// {tile value, 0, 0, 0} per uniform brick (fp32 in every format: the side of the
  /// isosurface a uniform brick reads is exact).
  std::vector<Sample> tiles;
  std::shared_ptr<const SamplePool> pool;                     ///< kFp32: slots * 729 samples
  std::shared_ptr<const std::vector<CompactSample>> compact;  ///< kFp16 / kUnorm16: slots * 729
  std::vector<BrickDecode> decode;                            ///< kUnorm16: one per slot
  /// kFp16: 1 / spacing_m per axis [1/m]: gradient = half_to_float(g[a]) * fp16_unscale[a].
  std::array<float, 3> fp16_unscale{1.f, 1.f, 1.f};
  /// Arena stores (session/live_field.h: one pool shared by the snapshots of an edited
  /// volume, unchanged bricks not copied): the slots the pool (and the decode table) hold;
  /// active table entries may name any slot below it, in any order. 0 (make_bricked_field):
  /// the slots are the active bricks' ranks, below active_bricks().
  std::size_t slot_capacity = 0;
  /// kUnorm16 arena stores: one BrickDecode per arena slot, shared by the arena's snapshots;
  /// used instead of `decode` when set.
  std::shared_ptr<const std::vector<BrickDecode>> shared_decode;

  /// Check the store against a grid of `dims` voxels (bricks, table size, pool and decode
  /// lengths, table entries in range) and record the read pointers FieldView uses; on
  /// failure it stays unsealed and returns false. Call after the last change (the store is
  /// immutable from then on); make_bricked_field does.
  bool seal(const std::array<int, 3>& dims) {
    sealed_ = {};
    const std::size_t nx = std::size_t(dims[0] + 7) >> 3, ny = std::size_t(dims[1] + 7) >> 3,
                      nz = std::size_t(dims[2] + 7) >> 3;
    if (dims[0] <= 0 || dims[1] <= 0 || dims[2] <= 0 || bricks[0] != int(nx) || bricks[1] != int(ny) ||
        bricks[2] != int(nz) || table.size() != nx * ny * nz || tiles.size() > table.size())
      return false;
    const std::size_t active = table.size() - tiles.size();
    const std::size_t slots = slot_capacity != 0 ? slot_capacity : active;
    if (slots > kMaxSlots || active > slots) return false;
    const std::size_t n = slots * kBrickSamples;
    if (format == SampleFormat::kFp32 ? (!pool || pool->size() < n) : (!compact || compact->size() < n)) return false;
    const std::vector<BrickDecode>& dec = shared_decode ? *shared_decode : decode;
    if (format == SampleFormat::kUnorm16 && dec.size() < slots) return false;
    // Entry checks without a branch or a division (a loop the compiler vectorises: it is
    // most of sealing a live field's snapshot after an edit): an active entry is a multiple
    // of kBrickSamples (odd) exactly when its product with the inverse of kBrickSamples
    // modulo 2^32 is at most (2^32 - 1) / kBrickSamples, and then below slots *
    // kBrickSamples exactly when its slot is below slots.
    constexpr std::uint32_t kInv = [] {
      std::uint32_t x = std::uint32_t(kBrickSamples);  // Newton: x = x (2 - k x), 4 bits -> 64
      for (int i = 0; i < 4; ++i) x *= 2u - std::uint32_t(kBrickSamples) * x;
      return x;
    }();
    static_assert(kInv * std::uint32_t(kBrickSamples) == 1u);
    constexpr std::uint32_t kMultiples = 0xFFFFFFFFu / std::uint32_t(kBrickSamples);
    const std::uint32_t n_tiles = std::uint32_t(tiles.size()), end = std::uint32_t(n);  // n < kUniform
    std::uint32_t bad = 0;
    for (std::uint32_t e : table) {
      const std::uint32_t uniform = e >> 31;
      const std::uint32_t bad_tile = (e & ~kUniform) >= n_tiles;
      const std::uint32_t bad_slot = (e * kInv > kMultiples) | (e >= end);
      bad |= (uniform & bad_tile) | ((uniform ^ 1u) & bad_slot);
    }
    if (bad) return false;
    sealed_ = {dims, table.data(), tiles.data(), format == SampleFormat::kFp32 ? pool->data() : nullptr,
               format == SampleFormat::kFp32 ? nullptr : compact->data(), nx, nx * ny,
               format == SampleFormat::kUnorm16 ? dec.data() : nullptr, dims[0] == 1 || dims[1] == 1 || dims[2] == 1};
    return true;
  }
  const Sealed& sealed() const { return sealed_; }

  std::size_t total_bricks() const { return table.size(); }
  std::size_t active_bricks() const { return table.size() - tiles.size(); }
  /// Sample `local` (0..728, i + 9 j + 81 k) of active slot `slot`, decoded to fp32.
  Sample stored(std::uint32_t slot, std::size_t local) const {
    const std::size_t i = std::size_t(slot) * kBrickSamples + local;
    if (format == SampleFormat::kFp32) return (*pool)[i];
    return decode_compact((*compact)[i], slot);
  }
  /// A compact sample of slot `slot` decoded (kFp16 or kUnorm16).
  Sample decode_compact(const CompactSample& c, std::uint32_t slot) const {
    if (format == SampleFormat::kFp16)
      return {half_to_float(c.value), half_to_float(c.g[0]) * fp16_unscale[0],
              half_to_float(c.g[1]) * fp16_unscale[1], half_to_float(c.g[2]) * fp16_unscale[2]};
    const BrickDecode& d = sealed_.decode != nullptr ? sealed_.decode[slot] : decode[slot];
    return {unorm16_to_float(c.value, d.offset[0], d.scale[0]), unorm16_to_float(c.g[0], d.offset[1], d.scale[1]),
            unorm16_to_float(c.g[1], d.offset[2], d.scale[2]), unorm16_to_float(c.g[2], d.offset[3], d.scale[3])};
  }

 private:
  Sealed sealed_;
};

/// The published sample field: dense (one Sample per voxel, x fastest, then y, then z) or
/// bricked (`bricks` set, `samples` empty). Immutable once published (engine/ publishes a
/// new one after each edit). Read it through core::FieldView (field_view.h), which reads
/// both the same way.
struct SampleField {
  Grid grid;
  std::vector<Sample> samples;  ///< dense: grid.voxel_count() entries; bricked: empty
  std::uint64_t version = 0;    ///< increases with every publication
  /// The value of every voxel outside the grid (its gradient is zero there): FieldView
  /// interpolates toward it across the border cells instead of clamping to the edge.
  /// NaN (the default) means "no data": outside every isosurface (iso_excess(NaN) < 0),
  /// so a HIP outside the volume is outside the object. A publisher that knows the
  /// isosurface sets a finite outside value (Isosurface::outside_value), which closes an
  /// object cut by the volume border with a surface half a voxel beyond the last sample.
  float background = std::numeric_limits<float>::quiet_NaN();
  /// The bricked representation (brick_field.h: make_bricked_field); null for a dense field.
  std::shared_ptr<const BrickStore> bricks;
  /// The voxels whose samples may differ from the previous version's: index space, [lo, hi)
  /// per axis. `known` false (the default: a first snapshot, a dense recompute): anything
  /// may have changed. The live field sets it from the bricks whose published entries
  /// changed; the servo leaves a new version that changed nothing near the probe alone.
  struct ChangedBox {
    std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
    bool known = false;
    bool empty() const { return lo[0] >= hi[0] || lo[1] >= hi[1] || lo[2] >= hi[2]; }
  };
  ChangedBox changed;

  bool bricked() const { return bricks != nullptr; }
};

/// The background value that puts everything outside `f`'s grid outside `iso`:
/// Isosurface::outside_value over the finite sample values (tau itself when there are
/// none). A scan of the samples: call it when publishing, never in the servo tick.
/// Bricked: the stored values inside the grid (pool, decoded) and the tiles. A tile keeps
/// only one bound of its brick's range, so the result can be nearer tau than on the dense
/// field the bricks came from (it is outside `iso` all the same).
inline float outside_background(const SampleField& f, const Isosurface& iso) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  auto add = [&](float v) {
    if (!(v == v) || v - v != 0.0f) return;  // NaN or Inf
    lo = v < lo ? v : lo;
    hi = v > hi ? v : hi;
  };
  for (const Sample& s : f.samples) add(s.value);
  if (f.bricks) {
    const BrickStore& b = *f.bricks;
    for (const Sample& t : b.tiles) add(t.value);
    for (std::size_t id = 0; id < b.table.size(); ++id) {
      if (b.table[id] & BrickStore::kUniform) continue;
      const int bx = int(id % std::size_t(b.bricks[0])), by = int(id / std::size_t(b.bricks[0]) % std::size_t(b.bricks[1])),
                bz = int(id / (std::size_t(b.bricks[0]) * std::size_t(b.bricks[1])));
      for (int k = 0; k < kBrickStored && kBrickSize * bz + k < f.grid.dims[2]; ++k)
        for (int j = 0; j < kBrickStored && kBrickSize * by + j < f.grid.dims[1]; ++j)
          for (int i = 0; i < kBrickStored && kBrickSize * bx + i < f.grid.dims[0]; ++i)
            add(b.stored(BrickStore::slot_of(b.table[id]), std::size_t(i + kBrickStored * j + kBrickStored * kBrickStored * k)).value);
    }
  }
  return float(iso.outside_value(lo, hi));
}

}  // namespace isotouch::core
