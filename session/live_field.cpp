// live_field.cpp - the edited volume's published snapshot, updated brick by brick. The design is in live_field.h. Compiled with -ffp-contract=off like the CPU
// reference it calls (engine/sparse_cpu.cpp), although every float operation on samples
// happens there: this file selects bricks, compares bits and moves samples.
#include "isotouch/session/live_field.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>

#include <sys/mman.h>
#include <unistd.h>

#include "isotouch/session/live_gpu.h"
#include "isotouch/engine/sparse_chain.h"

namespace isotouch::session {
using core::BrickStore;
using engine::Volume;
using engine::VolumeError;
namespace sparse = engine::sparse;

namespace {

using Clock = std::chrono::steady_clock;
using core::BrickStore;
constexpr std::size_t kS = core::kBrickSamples;  // 729 samples per slot

/// Recomputed bricks from which update() runs the filters on the GPU by default (see
/// live_field.h; measured in tests/test_live_field.cpp's DISABLED_BenchChestGpuCpu).
constexpr std::size_t kDefaultGpuMinBricks = 24;

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// floor(a / b) for b > 0 and any sign of a.
int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/// Sample memory of one slot [B]: 729 samples + the kUnorm16 decode parameters.
std::uint64_t slot_bytes(core::SampleFormat f) {
  return f == core::SampleFormat::kFp32 ? kS * sizeof(core::Sample)
                                        : kS * sizeof(core::CompactSample) +
                                              (f == core::SampleFormat::kUnorm16 ? sizeof(core::BrickDecode) : 0);
}

/// Arena slots for `active` active bricks: room for half as many again (at least 256) of
/// changed bricks before old snapshots held by someone force a copy into a new arena.
std::size_t capacity_for(std::size_t active) {
  return std::min(BrickStore::kMaxSlots, active + std::max<std::size_t>(active / 2, 256));
}

/// The pool memory shared by the snapshots of one LiveField (see live_field.h): a fixed
/// number of slots of 729 samples, never reallocated. The sample memory is written only
/// by update() (one thread) into slots no live snapshot uses; the bookkeeping of which
/// slots are free is under `mu`, shared with the stores' deleters (any thread).
struct Arena {
  Arena(std::size_t slots, core::SampleFormat f) : capacity(slots), format(f), born(slots, 0) {
    if (f == core::SampleFormat::kFp32) {
      pool = std::make_shared<core::SamplePool>(slots * kS, core::Sample{});
      samples = pool->data();
    } else {
      compact = std::make_shared<std::vector<core::CompactSample>>(slots * kS);
      codes = compact->data();
      if (f == core::SampleFormat::kUnorm16) {
        decode = std::make_shared<std::vector<core::BrickDecode>>(slots);
        params = decode->data();
      }
    }
    free_slots.reserve(slots);
    for (std::size_t s = slots; s-- > 0;) free_slots.push_back(std::uint32_t(s));  // pop order 0, 1, ...
    is_free.assign(slots, 1);
  }

  /// Takes `n` free slots into `out`; false (nothing taken) if fewer are free.
  bool take(std::size_t n, std::vector<std::uint32_t>& out) {
    std::lock_guard lock(mu);
    if (retired_ || free_slots.size() < n) return false;
    out.assign(free_slots.end() - std::ptrdiff_t(n), free_slots.end());
    free_slots.resize(free_slots.size() - n);
    for (std::uint32_t s : out) is_free[s] = 0;
    return true;
  }
  /// Slots taken but never published (update() failed).
  void give_back(const std::vector<std::uint32_t>& slots) {
    std::lock_guard lock(mu);
    free_slots.insert(free_slots.end(), slots.begin(), slots.end());
    for (std::uint32_t s : slots) is_free[s] = 1;
  }
  /// A new arena took over (update() copied the current bricks there): no slot of this one
  /// is taken again. The memory of every slot no live snapshot uses goes back to the system
  /// now, and that of each slot freed later when its last snapshot dies: a snapshot held for
  /// long (the first one, say) keeps its own slots resident, not the whole arena.
  /// `in_use`: the slots of the arena's newest store, which version `version` (in the new
  /// arena) no longer uses; each is freed once no live store of this arena uses it.
  void retire(std::uint64_t version, const std::vector<std::uint32_t>& in_use) noexcept {
    std::lock_guard lock(mu);
    retired_ = true;
    for (std::uint32_t s : in_use) retire_locked({s, born[s], version});
    for (std::size_t s = 0; s < capacity;) {
      if (!is_free[s]) {
        ++s;
        continue;
      }
      std::size_t e = s;
      while (e < capacity && is_free[e]) ++e;
      decommit(s, e);
      s = e;
    }
  }
  /// A store of `version` is about to be published: it uses `born` for the first time and
  /// no longer uses `retired` (slots of the previous store). Throws (bad_alloc) only before
  /// changing anything.
  void publish(std::uint64_t version, const std::vector<std::uint32_t>& born_slots,
               const std::vector<std::uint32_t>& retired) {
    std::lock_guard lock(mu);
    live.insert(version);
    for (std::uint32_t s : born_slots) born[s] = version;
    for (std::uint32_t s : retired) retire_locked({s, born[s], version});
  }
  /// The store of `version` died (its deleter, any thread).
  void release(std::uint64_t version) noexcept {
    std::lock_guard lock(mu);
    live.erase(version);
    auto node = blocked.extract(version);
    if (!node.empty())
      for (const Retired& r : node.mapped()) retire_locked(r);
  }
  std::size_t used() const {
    std::lock_guard lock(mu);
    return capacity - free_slots.size();
  }

  const std::size_t capacity;
  const core::SampleFormat format;
  std::shared_ptr<core::SamplePool> pool;                   ///< kFp32
  std::shared_ptr<std::vector<core::CompactSample>> compact;  ///< kFp16 / kUnorm16
  std::shared_ptr<std::vector<core::BrickDecode>> decode;   ///< kUnorm16
  core::Sample* samples = nullptr;                          ///< writable views of the above
  core::CompactSample* codes = nullptr;
  core::BrickDecode* params = nullptr;

 private:
  /// A slot used by store versions [born, retired).
  struct Retired {
    std::uint32_t slot;
    std::uint64_t born, retired;
  };
  /// Free `r` unless a live store of a version in [born, retired) uses it; then park it
  /// under the oldest such version, to be looked at again when that store dies.
  void retire_locked(const Retired& r) noexcept {
    try {
      const auto it = live.lower_bound(r.born);
      if (it != live.end() && *it < r.retired)
        blocked[*it].push_back(r);
      else
        free_locked(r.slot);
    } catch (...) {
      // Out of memory while parking: the slot is lost to this arena (never reused, so
      // never overwritten under a reader), which is safe.
    }
  }

  void free_locked(std::uint32_t slot) noexcept {
    free_slots.push_back(slot);  // capacity reserved: no allocation
    is_free[slot] = 1;
    if (!retired_) return;
    // The slot's own pages and those it shares with a free neighbour (a slot is larger than
    // a page, so a page spans two slots at most; a neighbour's other pages went with it).
    const std::size_t lo = slot > 0 && is_free[slot - 1] ? slot - 1 : slot;
    const std::size_t hi = std::size_t(slot) + 1 < capacity && is_free[slot + 1] ? slot + 2 : std::size_t(slot) + 1;
    decommit(lo, hi);
  }
  /// Gives the whole pages of slots [lo, hi) back to the system (madvise MADV_DONTNEED:
  /// the pages read as zeros if touched again; nothing reads a free slot of a retired
  /// arena). Pages shared with a slot outside the run are kept.
  void decommit(std::size_t lo, std::size_t hi) const noexcept {
    static const std::uintptr_t page = std::uintptr_t(::sysconf(_SC_PAGESIZE));
    char* base = samples ? reinterpret_cast<char*>(samples) : reinterpret_cast<char*>(codes);
    const std::size_t per = kS * (samples ? sizeof(core::Sample) : sizeof(core::CompactSample));
    const std::uintptr_t a = (reinterpret_cast<std::uintptr_t>(base + lo * per) + page - 1) / page * page;
    const std::uintptr_t b = reinterpret_cast<std::uintptr_t>(base + hi * per) / page * page;
    if (b > a) (void)::madvise(reinterpret_cast<void*>(a), b - a, MADV_DONTNEED);
  }

  mutable std::mutex mu;
  bool retired_ = false;
  std::vector<std::uint8_t> is_free;  ///< per slot: in free_slots
  std::vector<std::uint32_t> free_slots;
  std::vector<std::uint64_t> born;  ///< per slot: the first store version that uses it
  std::set<std::uint64_t> live;     ///< versions of the arena's stores alive now
  std::map<std::uint64_t, std::vector<Retired>> blocked;
};

/// Deleter of a published store: tells its arena (armed after publication; unarmed it
/// only deletes, for a store that was never published).
struct StoreDeleter {
  std::shared_ptr<Arena> arena;
  std::uint64_t version = 0;
  void operator()(const BrickStore* s) const noexcept {
    if (arena) arena->release(version);
    delete s;
  }
};

std::uint32_t bits(float f) { return std::bit_cast<std::uint32_t>(f); }

/// One brick whose published entry changes in this update.
struct Change {
  std::uint32_t id = 0;
  bool active = false;
  float tile = 0;           ///< uniform: the tile value
  std::size_t scratch = 0;  ///< active: index of its samples in the update's scratch
  std::uint32_t slot = 0;   ///< active: the arena slot it is written to
};

}  // namespace

struct LiveField::Impl {
  LiveFieldOptions opt;
  core::Grid grid;
  std::string path;
  sparse::Plan plan;
  std::array<int, 3> nb{0, 0, 0};
  std::size_t total = 0;
  std::vector<float> shadow;             ///< the raw voxels as of `cur`
  sparse::RawRanges raw;                 ///< their per-brick ranges
  std::vector<std::uint8_t> candidate;   ///< per brick: select() made it a candidate (as of `cur`)
  std::vector<std::uint32_t> tile_owner; ///< per tile of cur's store: its brick (capacity: every brick)
  std::function<void()> commit_fault;    ///< set_commit_fault_for_test
  std::shared_ptr<Arena> arena;          ///< cur's arena
  std::vector<std::weak_ptr<Arena>> old_arenas;
  std::shared_ptr<const core::SampleField> cur;
  std::uint64_t version = 0;  ///< cur's SampleField::version
  // Per-update scratch, by generation (no clearing).
  std::vector<std::uint32_t> work_mark, content_mark, dirty_mark;
  std::uint32_t gen = 0;
  /// This update's boxes of voxels whose bits changed (lo x, y, z, hi x, y, z; one per changed
  /// dirty brick, find_work): a brick's selection reads only its window, so one whose window
  /// meets none of them keeps the selection it had (`candidate`, and its tile).
  std::vector<std::array<int, 6>> changed_boxes;
  /// Whether brick `id`'s selection window (select_brick's: the brick +- 1 + R voxels,
  /// clamped to the grid) holds a voxel of `changed_boxes`.
  bool window_changed(std::uint32_t id) const {
    const auto b = core::brick_coords(id, nb);
    for (const auto& box : changed_boxes) {
      bool meets = true;
      for (int a = 0; a < 3 && meets; ++a) {
        const std::size_t k = std::size_t(a);
        const auto [lo, hi] = sparse::brick_window(b[k], plan.radius[k], grid.dims[k]);
        meets = lo <= box[k + 3] && box[k] <= hi;
      }
      if (meets) return true;
    }
    return false;
  }
  // The GPU recompute (live_gpu.h), null where not used (gpu_reason says why).
  std::unique_ptr<LiveGpuFilter> gpu;
  std::string gpu_reason = "no Vulkan context given";
  std::size_t gpu_min_bricks = kDefaultGpuMinBricks;

  /// The GPU filters on `recompute` (LiveGpuFilter::filter), or null where the GPU failed: the
  /// GPU is then dropped for good (a lost device, no memory, a work list past the device's
  /// texel limit), gpu_reason says why, st says the CPU ran, and this update goes on there.
  const float* gpu_filter_or_drop(const std::vector<std::uint32_t>& recompute, LiveUpdateStats& st) {
    try {
      return gpu->filter(recompute, st.gpu_submit_ms);
    } catch (const std::exception& e) {
      gpu_reason = std::string("the GPU failed on an update of ") + std::to_string(recompute.size()) +
                   " bricks (" + e.what() + "): the CPU recomputes from then on";
      gpu.reset();
      st.gpu = false;
      st.gpu_submit_ms = 0;
      st.gpu_failed = true;
      return nullptr;
    }
  }

  void next_gen() {
    if (++gen == 0) {
      std::fill(work_mark.begin(), work_mark.end(), 0u);
      std::fill(content_mark.begin(), content_mark.end(), 0u);
      std::fill(dirty_mark.begin(), dirty_mark.end(), 0u);
      gen = 1;
    }
  }

  /// Refuses a sample value that the format cannot hold (as core::make_bricked_field does).
  void check_storable(const core::Sample* s, std::uint32_t id) const {
    if (opt.format == core::SampleFormat::kFp32) return;
    for (std::size_t l = 0; l < kS; ++l)
      if (const std::string why = core::detail::compact_refusal(s[l].value, opt.format); !why.empty())
        throw std::invalid_argument("live field '" + path + "': brick " + std::to_string(id) + " sample " +
                                    std::to_string(l) + " value = " + std::to_string(s[l].value) +
                                    " cannot be stored as " + core::to_string(opt.format) + why + "; use fp32 samples");
  }

  /// Writes brick `id`'s 729 fp32 samples into `slot` of `a`, in the arena's format.
  void write_slot(Arena& a, std::uint32_t slot, std::uint32_t id, const core::Sample* s) const {
    if (a.format == core::SampleFormat::kFp32) {
      std::memcpy(a.samples + std::size_t(slot) * kS, s, kS * sizeof(core::Sample));
      return;
    }
    core::BrickDecode unused{};
    core::detail::encode_brick(grid, core::brick_coords(id, nb), s, a.format, a.codes + std::size_t(slot) * kS,
                               a.params ? a.params[slot] : unused);
  }

  /// Copies slot `from` of `src` to slot `to` of `dst` (same format).
  static void copy_slot(const Arena& src, std::uint32_t from, Arena& dst, std::uint32_t to) {
    if (src.format == core::SampleFormat::kFp32) {
      std::memcpy(dst.samples + std::size_t(to) * kS, src.samples + std::size_t(from) * kS, kS * sizeof(core::Sample));
      return;
    }
    std::memcpy(dst.codes + std::size_t(to) * kS, src.codes + std::size_t(from) * kS, kS * sizeof(core::CompactSample));
    if (src.params) dst.params[to] = src.params[from];
  }

  /// The new samples `s` of brick `id` equal, bit for bit once stored, slot `slot` of `a`.
  bool same_as_slot(const Arena& a, std::uint32_t slot, std::uint32_t id, const core::Sample* s) const {
    if (a.format == core::SampleFormat::kFp32)
      return std::memcmp(a.samples + std::size_t(slot) * kS, s, kS * sizeof(core::Sample)) == 0;
    core::CompactSample enc[kS];
    core::BrickDecode d{};
    core::detail::encode_brick(grid, core::brick_coords(id, nb), s, a.format, enc, d);
    if (std::memcmp(a.codes + std::size_t(slot) * kS, enc, sizeof enc) != 0) return false;
    return !a.params || std::memcmp(&a.params[slot], &d, sizeof d) == 0;
  }

  /// A store over arena `a` with the given table and tiles, sealed.
  std::unique_ptr<BrickStore> make_store(const Arena& a, std::vector<std::uint32_t> table,
                                         std::vector<core::Sample> tiles) const {
    auto st = std::make_unique<BrickStore>();
    st->bricks = nb;
    st->format = opt.format;
    st->table = std::move(table);
    st->tiles = std::move(tiles);
    st->slot_capacity = a.capacity;
    st->pool = a.pool;
    st->compact = a.compact;
    st->shared_decode = a.decode;
    if (opt.format != core::SampleFormat::kFp32)
      st->fp16_unscale = {float(1.0 / grid.spacing_m.x), float(1.0 / grid.spacing_m.y), float(1.0 / grid.spacing_m.z)};
    if (!st->seal(grid.dims)) {  // a bug of this file: say which entry
      std::string first = "none out of range";
      for (std::size_t id = 0; id < st->table.size(); ++id) {
        const std::uint32_t e = st->table[id];
        if ((e & BrickStore::kUniform) ? (e & ~BrickStore::kUniform) >= st->tiles.size()
                                       : (e % kS != 0 || e / kS >= a.capacity)) {
          first = "brick " + std::to_string(id) + " entry " + std::to_string(e);
          break;
        }
      }
      throw std::logic_error("live field '" + path + "': the built store does not seal (internal error; table " +
                             std::to_string(st->table.size()) + ", tiles " + std::to_string(st->tiles.size()) +
                             ", arena slots " + std::to_string(a.capacity) + ", first bad entry: " + first + ")");
    }
    return st;
  }

  /// Publishes `store` (over `a`) as version `v`: registers it with the arena, whose slots
  /// `born` it uses first and `retired` it no longer uses. Nothing after the arena's
  /// publish can fail.
  std::shared_ptr<const core::SampleField> publish(std::unique_ptr<BrickStore> store, const std::shared_ptr<Arena>& a,
                                                   std::uint64_t v, const std::vector<std::uint32_t>& born,
                                                   const std::vector<std::uint32_t>& retired,
                                                   const core::SampleField::ChangedBox& changed = {}) const {
    std::shared_ptr<const BrickStore> sp(store.release(), StoreDeleter{});
    auto field = std::make_shared<core::SampleField>();
    field->grid = grid;
    field->background = opt.background;
    field->version = v;
    field->changed = changed;
    field->bricks = sp;
    a->publish(v, born, retired);
    StoreDeleter* d = std::get_deleter<StoreDeleter>(sp);
    d->arena = a;
    d->version = v;
    return field;
  }

  /// The first snapshot (version 1), everything computed: run_sparse_cpu's steps, the
  /// active bricks written into a new arena.
  void build(const Volume& vol);
  /// The bricks whose content or selection the edit of `dirty` can change; updates `raw`
  /// (old entries saved in `raw_undo`) and fills `changed` (dirty bricks whose bits changed).
  void find_work(const Volume& vol, const std::vector<std::uint32_t>& dirty, std::vector<std::uint32_t>& work,
                 std::vector<std::uint32_t>& changed, std::vector<std::pair<std::uint32_t, std::array<float, 3>>>& raw_undo);
};

void LiveField::Impl::build(const Volume& vol) {
  raw.init(grid);
  const std::size_t slice = std::size_t(grid.dims[0]) * std::size_t(grid.dims[1]);
  for (int z = 0; z < grid.dims[2]; ++z) raw.add_slice(grid, z, vol.voxels.data() + std::size_t(z) * slice);
  const sparse::Selection sel = sparse::select(grid, vol.voxels.data(), plan, opt.iso);
  candidate.assign(total, 0);
  for (std::uint32_t id : sel.candidates) candidate[id] = 1;
  std::vector<float> tile(total, 0.f);
  for (std::size_t id = 0; id < total; ++id)
    if (!candidate[id] && !core::tile_value(sel.lo[id], sel.hi[id], opt.iso, opt.background, tile[id]))
      throw std::logic_error("live field: brick " + std::to_string(id) + " straddles but is no candidate");
  sparse::CandidateCpu cpu(vol, plan);
  std::vector<core::Sample> samples;
  std::vector<std::uint32_t> active;
  for (std::uint32_t id : sel.candidates) {
    const sparse::CandidateRange r = cpu.range(id);
    if (!sparse::is_active(r, opt.iso, opt.background, tile[id])) continue;
    samples.resize(samples.size() + kS);
    cpu.samples(samples.data() + samples.size() - kS, opt.background);
    check_storable(samples.data() + samples.size() - kS, id);
    active.push_back(id);
  }
  auto a = std::make_shared<Arena>(capacity_for(active.size()), opt.format);
  std::vector<std::uint32_t> slots;
  if (!a->take(active.size(), slots)) throw std::logic_error("live field: arena smaller than its first snapshot");
  std::vector<std::uint32_t> table(total);
  std::vector<core::Sample> tiles;
  tiles.reserve(total - active.size());
  tile_owner.clear();
  tile_owner.reserve(total);
  for (std::size_t id = 0, k = 0; id < total; ++id) {
    if (k < active.size() && active[k] == id) {
      write_slot(*a, slots[k], std::uint32_t(id), samples.data() + k * kS);
      table[id] = slots[k] * std::uint32_t(kS);
      ++k;
    } else {
      table[id] = BrickStore::kUniform | std::uint32_t(tiles.size());
      tiles.push_back({tile[id], 0.f, 0.f, 0.f});
      tile_owner.push_back(std::uint32_t(id));
    }
  }
  cur = publish(make_store(*a, std::move(table), std::move(tiles)), a, 1, slots, {});
  arena = std::move(a);
  version = 1;
}

void LiveField::Impl::find_work(const Volume& vol, const std::vector<std::uint32_t>& dirty,
                                std::vector<std::uint32_t>& work, std::vector<std::uint32_t>& changed,
                                std::vector<std::pair<std::uint32_t, std::array<float, 3>>>& raw_undo) {
  const int nx = grid.dims[0], ny = grid.dims[1];
  auto mark_box = [&](const int lo[3], const int hi[3], bool content) {
    for (int z = std::max(lo[2], 0); z <= std::min(hi[2], nb[2] - 1); ++z)
      for (int y = std::max(lo[1], 0); y <= std::min(hi[1], nb[1] - 1); ++y)
        for (int x = std::max(lo[0], 0); x <= std::min(hi[0], nb[0] - 1); ++x) {
          const std::uint32_t id = std::uint32_t((std::size_t(z) * std::size_t(nb[1]) + std::size_t(y)) * std::size_t(nb[0]) + std::size_t(x));
          if (work_mark[id] != gen) {
            work_mark[id] = gen;
            work.push_back(id);
          }
          if (content) content_mark[id] = gen;
        }
  };
  for (std::uint32_t d : dirty) {
    if (dirty_mark[d] == gen) continue;  // duplicate
    dirty_mark[d] = gen;
    // The box of voxels whose bits changed (the shadow is the volume as of `cur`).
    const auto b = core::brick_coords(d, nb);
    int lo[3] = {1 << 30, 1 << 30, 1 << 30}, hi[3] = {-1, -1, -1};
    const int x0 = 8 * b[0], x1 = std::min(x0 + 8, nx), y0 = 8 * b[1], y1 = std::min(y0 + 8, ny), z0 = 8 * b[2],
              z1 = std::min(z0 + 8, grid.dims[2]);
    for (int z = z0; z < z1; ++z)
      for (int y = y0; y < y1; ++y) {
        const std::size_t row = (std::size_t(z) * std::size_t(ny) + std::size_t(y)) * std::size_t(nx);
        const float* now = vol.voxels.data() + row;
        const float* was = shadow.data() + row;
        if (std::memcmp(now + x0, was + x0, std::size_t(x1 - x0) * sizeof(float)) == 0) continue;
        for (int x = x0; x < x1; ++x)
          if (bits(now[x]) != bits(was[x])) {
            lo[0] = std::min(lo[0], x);
            hi[0] = std::max(hi[0], x);
          }
        lo[1] = std::min(lo[1], y);
        hi[1] = std::max(hi[1], y);
        lo[2] = std::min(lo[2], z);
        hi[2] = std::max(hi[2], z);
      }
    if (hi[0] < 0) continue;  // listed, but no bit changed
    changed.push_back(d);
    changed_boxes.push_back({lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]});
    // Content: brick c reads raw voxels [8c - 1 - R, 8c + 9 + R] (exact range over the
    // smoothed brick +- 1 voxel; samples up to the apron 8c + 8, whose gradient reads 8c + 9).
    int clo[3], chi[3];
    for (int a = 0; a < 3; ++a) {
      const int r = plan.radius[std::size_t(a)];
      clo[a] = floor_div(lo[a] - 9 - r + 7, 8);  // ceil((lo - 9 - R) / 8)
      chi[a] = floor_div(hi[a] + 1 + r, 8);
    }
    mark_box(clo, chi, true);
    // Selection: the raw range of d feeds the widened range of the bricks within reach.
    const std::array<float, 3> old{raw.lo[d], raw.hi[d], raw.nan[d] ? 1.f : 0.f};
    raw.set_brick(grid, vol.voxels.data(), d);
    if (bits(raw.lo[d]) != bits(old[0]) || bits(raw.hi[d]) != bits(old[1]) || (raw.nan[d] != 0) != (old[2] != 0)) {
      raw_undo.push_back({d, old});
      int slo[3], shi[3];
      for (int a = 0; a < 3; ++a) {
        slo[a] = b[std::size_t(a)] - plan.reach[std::size_t(a)];
        shi[a] = b[std::size_t(a)] + plan.reach[std::size_t(a)];
      }
      mark_box(slo, shi, false);
    }
  }
}

LiveField::LiveField(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
LiveField::~LiveField() = default;

std::unique_ptr<LiveField> LiveField::create(const Volume& vol, const LiveFieldOptions& options) {
  return create(vol, options, nullptr);
}

std::unique_ptr<LiveField> LiveField::create(const Volume& vol, const LiveFieldOptions& options,
                                             GpuParts gpu) {
  const std::string why = sparse::validate(options.passes);
  if (!why.empty()) throw std::invalid_argument("live field: " + why);
  if (vol.grid.empty() || vol.voxels.size() != vol.grid.voxel_count())
    throw VolumeError(vol.path + ": live field: " + std::to_string(vol.voxels.size()) + " voxels for dims " +
                      std::to_string(vol.grid.dims[0]) + "x" + std::to_string(vol.grid.dims[1]) + "x" +
                      std::to_string(vol.grid.dims[2]));
  auto impl = std::make_unique<Impl>();
  impl->opt = options;
  impl->grid = vol.grid;
  impl->path = vol.path;
  impl->plan = sparse::make_plan(vol.grid, options.passes, vol.path);
  impl->nb = core::brick_counts(vol.grid);
  impl->total = std::size_t(impl->nb[0]) * std::size_t(impl->nb[1]) * std::size_t(impl->nb[2]);
  impl->shadow = vol.voxels;
  impl->work_mark.assign(impl->total, 0);
  impl->content_mark.assign(impl->total, 0);
  impl->dirty_mark.assign(impl->total, 0);
  impl->build(vol);
  if (gpu) {
    if (impl->plan.ops.empty()) {
      impl->gpu_reason = "no filter in the pass list (" + impl->plan.text + "): the gradient needs no GPU pass";
    } else {
      auto g = gpu.live_filter(*gpu.ctx, vol, options.passes);
      if (g) {
        impl->gpu = std::move(*g.value);
        impl->gpu_reason.clear();
      } else {
        impl->gpu_reason = g.error;
      }
    }
  }
  return std::unique_ptr<LiveField>(new LiveField(std::move(impl)));
}

std::shared_ptr<const core::SampleField> LiveField::update(const Volume& vol, const std::vector<std::uint32_t>& dirty,
                                                           LiveUpdateStats* stats, const OnCommit& on_commit) {
  const auto t0 = Clock::now();
  Impl& m = *impl_;
  for (std::uint32_t id : dirty)
    if (id >= m.total)
      throw std::out_of_range("live field: dirty brick id " + std::to_string(id) + " is out of range (" +
                              std::to_string(m.total) + " bricks)");
  if (vol.grid.dims != m.grid.dims || vol.voxels.size() != m.shadow.size())
    throw std::invalid_argument("live field: volume '" + vol.path + "' has dims " + std::to_string(vol.grid.dims[0]) +
                                "x" + std::to_string(vol.grid.dims[1]) + "x" + std::to_string(vol.grid.dims[2]) +
                                " and " + std::to_string(vol.voxels.size()) + " voxels; the live field holds " +
                                std::to_string(m.grid.dims[0]) + "x" + std::to_string(m.grid.dims[1]) + "x" +
                                std::to_string(m.grid.dims[2]));
  LiveUpdateStats st;
  st.dirty = dirty.size();
  const BrickStore& old = *m.cur->bricks;
  const core::SampleFormat fmt = m.opt.format;
  m.next_gen();

  std::vector<std::uint32_t> work, changed, taken;
  std::vector<std::pair<std::uint32_t, std::array<float, 3>>> raw_undo;
  std::shared_ptr<Arena> fresh;  // a new arena when the current one is full
  std::vector<std::uint32_t> retiring;  // then: the slots the current arena's newest store uses
  // tile_owner's changes, to undo them in reverse if the update throws: a tile dropped (its
  // index, its owner, the last tile's owner that took its place) or a tile appended (kPushed).
  struct OwnerUndo {
    std::uint32_t at, owner, last;
  };
  constexpr std::uint32_t kPushed = ~std::uint32_t(0);
  std::vector<OwnerUndo> owner_undo;
  try {
    // 1. What the edit can change, then the new state of those bricks.
    m.changed_boxes.clear();
    m.find_work(vol, dirty, work, changed, raw_undo);
    std::sort(work.begin(), work.end());
    if (m.gpu) m.gpu->set_bricks(vol.voxels.data(), changed);  // the device's copy follows the volume
    std::vector<Change> changes;
    std::vector<std::pair<std::uint32_t, std::uint8_t>> cand_changes;
    std::vector<core::Sample> scratch;
    // 1a. The selection of every brick the edit reaches; which ones to recompute.
    enum class Todo : std::uint8_t { kKeep, kTile, kRecompute };
    std::vector<Todo> todo(work.size(), Todo::kKeep);
    std::vector<float> tile_of(work.size(), 0.f);
    std::vector<std::uint32_t> recompute;  // ascending (work is sorted)
    for (std::size_t w = 0; w < work.size(); ++w) {
      const std::uint32_t id = work[w];
      if (!m.window_changed(id)) {
        // Its selection is the last one (no voxel it reads changed): a brick that was no
        // candidate keeps its tile; a candidate is recomputed only where its samples read a
        // changed voxel. (select_brick here would give the same, at ~1000 voxel loads.)
        if (m.candidate[id] && m.content_mark[id] == m.gen) {
          todo[w] = Todo::kRecompute;
          recompute.push_back(id);
        }
        continue;
      }
      const sparse::BrickSelection sel = sparse::select_brick(m.grid, vol.voxels.data(), m.plan, m.opt.iso, id);
      if (std::uint8_t(sel.candidate) != m.candidate[id]) cand_changes.push_back({id, std::uint8_t(sel.candidate)});
      if (!sel.candidate) {
        if (!core::tile_value(sel.lo, sel.hi, m.opt.iso, m.opt.background, tile_of[w]))
          throw std::logic_error("live field: brick " + std::to_string(id) + " straddles but is no candidate");
        todo[w] = Todo::kTile;
      } else if (m.content_mark[id] != m.gen && m.candidate[id]) {
        continue;  // still a candidate, nothing it reads changed: as before
      } else {
        todo[w] = Todo::kRecompute;
        recompute.push_back(id);
      }
    }
    // 1b. Their exact ranges and the active ones' samples: the filters on the GPU (the list
    // kernels over the recomputed bricks' extents), ranges and samples from that output on
    // the host as the sparse chain does; or each brick on the CPU (run_sparse_cpu's code).
    st.recomputed = recompute.size();
    std::vector<sparse::CandidateRange> ranges;
    std::vector<std::size_t> sample_at(recompute.size(), SIZE_MAX);
    st.gpu = m.gpu && !recompute.empty() && recompute.size() >= m.gpu_min_bricks;
    const float* filtered = st.gpu ? m.gpu_filter_or_drop(recompute, st) : nullptr;
    if (filtered) {
      ranges = sparse::candidate_ranges(m.grid, filtered, recompute);
      for (std::size_t r = 0; r < recompute.size(); ++r) {
        float tile = 0;
        if (!sparse::is_active(ranges[r], m.opt.iso, m.opt.background, tile)) continue;
        sample_at[r] = scratch.size();
        scratch.resize(scratch.size() + kS);
        sparse::brick_samples(m.grid, filtered, core::brick_coords(recompute[r], m.nb), m.opt.background,
                              scratch.data() + sample_at[r]);
      }
    } else if (!recompute.empty()) {  // (also where the GPU just failed: this edit is not lost)
      sparse::CandidateCpu cpu(vol, m.plan);
      ranges.resize(recompute.size());
      for (std::size_t r = 0; r < recompute.size(); ++r) {
        ranges[r] = cpu.range(recompute[r]);
        float tile = 0;
        if (!sparse::is_active(ranges[r], m.opt.iso, m.opt.background, tile)) continue;
        sample_at[r] = scratch.size();
        scratch.resize(scratch.size() + kS);
        cpu.samples(scratch.data() + sample_at[r], m.opt.background);
      }
    }
    // 1c. The new state of those bricks, in brick order.
    for (std::size_t w = 0, r = 0; w < work.size(); ++w) {
      if (todo[w] == Todo::kKeep) continue;
      const std::uint32_t id = work[w];
      Change c;
      c.id = id;
      if (todo[w] == Todo::kTile) {
        c.tile = tile_of[w];
      } else {
        if (sparse::is_active(ranges[r], m.opt.iso, m.opt.background, c.tile)) {
          c.active = true;
          c.scratch = sample_at[r];
          m.check_storable(scratch.data() + c.scratch, id);
        }
        ++r;
      }
      // Keep what did not change: the same tile bits, or the same stored samples.
      const std::uint32_t e = old.table[id];
      const bool was_uniform = (e & BrickStore::kUniform) != 0;
      if (!c.active && was_uniform && bits(old.tiles[e & ~BrickStore::kUniform].value) == bits(c.tile)) continue;
      if (c.active && !was_uniform &&
          m.same_as_slot(*m.arena, BrickStore::slot_of(e), id, scratch.data() + c.scratch))
        continue;
      changes.push_back(c);
    }
    const auto t1 = Clock::now();
    st.recompute_ms = ms_between(t0, t1);

    // 2. Slots for the changed active bricks; a new arena if the current one is full.
    std::size_t need = 0, activated = 0, deactivated = 0;
    for (const Change& c : changes) {
      need += c.active;
      const bool was_uniform = (old.table[c.id] & BrickStore::kUniform) != 0;
      activated += c.active && was_uniform;
      deactivated += !c.active && !was_uniform;
    }
    std::vector<std::uint32_t> table = old.table;
    std::vector<core::Sample> tiles;
    tiles.reserve(old.tiles.size() + deactivated);  // (one copy: no reallocation below)
    tiles.assign(old.tiles.begin(), old.tiles.end());
    owner_undo.reserve(changes.size());  // tile_owner is changed in place (below), undone on a throw
    std::vector<std::uint32_t> born;
    Arena* target = m.arena.get();
    if (!m.arena->take(need, taken)) {
      // Old snapshots hold the free slots: copy the bricks that stay into a new arena.
      const std::size_t active_new = old.active_bricks() + activated - deactivated;
      fresh = std::make_shared<Arena>(capacity_for(active_new), fmt);
      for (std::uint32_t e : old.table)
        if (!(e & BrickStore::kUniform)) retiring.push_back(BrickStore::slot_of(e));
      std::vector<std::uint8_t> moving(m.total, 0);
      for (const Change& c : changes) moving[c.id] = 1;
      std::vector<std::uint32_t> keep;
      for (std::size_t id = 0; id < m.total; ++id)
        if (!(table[id] & BrickStore::kUniform) && !moving[id]) keep.push_back(std::uint32_t(id));
      if (!fresh->take(keep.size(), born)) throw std::logic_error("live field: new arena too small");
      for (std::size_t k = 0; k < keep.size(); ++k) {
        Impl::copy_slot(*m.arena, BrickStore::slot_of(table[keep[k]]), *fresh, born[k]);
        table[keep[k]] = born[k] * std::uint32_t(kS);
      }
      if (!fresh->take(need, taken)) throw std::logic_error("live field: new arena too small");
      target = fresh.get();
      st.new_bytes += std::uint64_t(keep.size()) * slot_bytes(fmt);
    }

    // 3. Write the new slots (no live snapshot uses them) and patch the table and tiles.
    std::vector<std::uint32_t> retired;
    std::size_t k = 0;
    for (Change& c : changes) {
      const std::uint32_t e = table[c.id];
      const bool was_uniform = (e & BrickStore::kUniform) != 0;
      if (!was_uniform && !fresh) retired.push_back(BrickStore::slot_of(e));
      if (c.active) {
        c.slot = taken[k++];
        m.write_slot(*target, c.slot, c.id, scratch.data() + c.scratch);
        if (was_uniform) {  // drop its tile: the last tile takes its index
          const std::uint32_t t = e & ~BrickStore::kUniform;
          std::vector<std::uint32_t>& owner = m.tile_owner;
          owner_undo.push_back({t, owner[t], owner.back()});
          tiles[t] = tiles.back();
          owner[t] = owner.back();
          table[owner[t]] = BrickStore::kUniform | t;
          tiles.pop_back();
          owner.pop_back();
        }
        table[c.id] = c.slot * std::uint32_t(kS);
      } else if (was_uniform) {
        tiles[e & ~BrickStore::kUniform] = {c.tile, 0.f, 0.f, 0.f};
      } else {
        table[c.id] = BrickStore::kUniform | std::uint32_t(tiles.size());
        tiles.push_back({c.tile, 0.f, 0.f, 0.f});
        owner_undo.push_back({kPushed, 0, 0});
        m.tile_owner.push_back(c.id);  // within its capacity (every brick): no allocation
      }
    }
    born.insert(born.end(), taken.begin(), taken.end());
    if (m.commit_fault) m.commit_fault();
    st.new_bytes += std::uint64_t(need) * slot_bytes(fmt);
    st.activated = activated;
    st.deactivated = deactivated;

    // 4. Publish: a new store when an entry changed, else the same store under a new version.
    const std::uint64_t v = m.version + 1;
    core::SampleField::ChangedBox box;  // the voxels of the bricks whose entries changed
    box.known = true;
    box.lo = {m.grid.dims[0], m.grid.dims[1], m.grid.dims[2]};
    for (const Change& c : changes) {
      const auto b = core::brick_coords(c.id, m.nb);
      for (int a = 0; a < 3; ++a) {
        box.lo[a] = std::min(box.lo[a], 8 * b[a]);
        box.hi[a] = std::max(box.hi[a], std::min(8 * b[a] + 8, m.grid.dims[a]));
      }
    }
    if (fresh) m.old_arenas.reserve(m.old_arenas.size() + 1);  // no allocation after publishing
    std::shared_ptr<const core::SampleField> next;
    if (changes.empty() && !fresh) {
      auto f = std::make_shared<core::SampleField>(*m.cur);
      f->version = v;
      f->changed = box;  // nothing
      next = std::move(f);
    } else {
      const std::shared_ptr<Arena>& a = fresh ? fresh : m.arena;
      next = m.publish(m.make_store(*a, std::move(table), std::move(tiles)), a, v, born, retired, box);
    }
    // Committed: nothing below throws.
    taken.clear();
    raw_undo.clear();
    for (const auto& [id, flag] : cand_changes) m.candidate[id] = flag;
    owner_undo.clear();
    if (fresh) {
      m.arena->retire(v, retiring);
      m.old_arenas.push_back(m.arena);
      m.arena = fresh;
      std::erase_if(m.old_arenas, [](const std::weak_ptr<Arena>& w) { return w.expired(); });
    }
    m.cur = std::move(next);
    m.version = v;
    st.active = m.cur->bricks->active_bricks();
    st.shared = fresh ? 0 : st.active - need;
    st.version = v;
    const auto t2 = Clock::now();
    st.publish_ms = ms_between(t1, t2);
    st.total_ms = ms_between(t0, t2);
  } catch (...) {
    // Nothing was published: the raw ranges, the slots and the device's copy of the volume
    // (the shadow: the volume as of the current snapshot) go back as they were.
    if (m.gpu) m.gpu->set_bricks(m.shadow.data(), changed);
    for (auto it = raw_undo.rbegin(); it != raw_undo.rend(); ++it) {
      m.raw.lo[it->first] = it->second[0];
      m.raw.hi[it->first] = it->second[1];
      m.raw.nan[it->first] = it->second[2] != 0.f ? 1 : 0;
    }
    if (!taken.empty() && !fresh) m.arena->give_back(taken);
    for (auto it = owner_undo.rbegin(); it != owner_undo.rend(); ++it) {
      if (it->at == kPushed) {
        m.tile_owner.pop_back();
      } else {
        m.tile_owner.push_back(it->last);  // (back where it was popped: within capacity)
        m.tile_owner[it->at] = it->owner;
      }
    }
    throw;
  }
  if (stats) *stats = st;
  if (on_commit) [&]() noexcept { on_commit(m.cur); }();
  for (std::uint32_t d : changed)  // the shadow follows the published volume
    core::copy_brick_voxels(m.grid, d, vol.voxels.data(), m.shadow.data());
  return m.cur;
}

const std::vector<float>& LiveField::published_voxels() const { return impl_->shadow; }
std::shared_ptr<const core::SampleField> LiveField::current() const { return impl_->cur; }
const LiveFieldOptions& LiveField::options() const { return impl_->opt; }

std::uint64_t LiveField::pool_bytes() const {
  std::uint64_t slots = impl_->arena->used();
  for (const auto& w : impl_->old_arenas)
    if (auto a = w.lock()) slots += a->used();
  return slots * slot_bytes(impl_->opt.format);
}

bool LiveField::gpu_enabled() const { return impl_->gpu != nullptr; }
const std::string& LiveField::gpu_reason() const { return impl_->gpu_reason; }
std::size_t LiveField::gpu_min_bricks() const { return impl_->gpu_min_bricks; }
void LiveField::set_gpu_min_bricks(std::size_t bricks) { impl_->gpu_min_bricks = bricks; }
void LiveField::set_commit_fault_for_test(std::function<void()> fault) { impl_->commit_fault = std::move(fault); }
void LiveField::set_gpu_filter(std::unique_ptr<LiveGpuFilter> filter, const std::string& reason_if_none) {
  impl_->gpu = std::move(filter);
  impl_->gpu_reason = impl_->gpu ? std::string() : reason_if_none;
}

std::string LiveField::describe() const {
  const Impl& m = *impl_;
  std::string s = "live field: " + m.plan.text + "; recompute: ";
  if (!m.gpu)
    return s + "CPU per brick (sparse::CandidateCpu, run_sparse_cpu's code); GPU not used: " + m.gpu_reason;
  return s + "GPU for updates of >= " + std::to_string(m.gpu_min_bricks) +
         " recomputed bricks (ranges and samples then on the host), CPU per brick below; " + m.gpu->describe();
}

std::uint64_t LiveField::arena_bytes() const {
  std::uint64_t slots = impl_->arena->capacity;
  for (const auto& w : impl_->old_arenas)
    if (auto a = w.lock()) slots += a->capacity;
  return slots * slot_bytes(impl_->opt.format);
}

}  // namespace isotouch::session
