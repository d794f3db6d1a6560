// edit_floor.cpp - EditFloor (bench/edit_floor.h).
#include "isotouch/bench/edit_floor.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "isotouch/core/brick_field.h"

namespace isotouch::bench {
namespace sparse = engine::sparse;
using core::BrickStore;

namespace {
using Clock = std::chrono::steady_clock;
constexpr std::size_t kS = core::kBrickSamples;
/// Snapshots a slot may still be read by after its brick moved: the triple buffer holds three.
constexpr std::uint64_t kSlotDelay = 4;
double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}
int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
}  // namespace

EditFloor::EditFloor(const engine::Volume& vol, const core::SampleField& first,
                     const std::vector<engine::PassDesc>& passes, const core::Isosurface& iso, std::size_t spare_slots)
    : vol_(vol), plan_(sparse::make_plan(vol.grid, passes, vol.path)), iso_(iso) {
  const BrickStore* st = first.bricks.get();
  if (!st || st->format != core::SampleFormat::kFp32 || !st->pool)
    throw std::invalid_argument("edit floor: the first snapshot of " + vol.path + " is not a bricked fp32 one");
  auto proto = std::make_shared<core::SampleField>(first);  // its grid, background, ...
  proto->bricks = nullptr;
  proto_ = proto;
  const std::size_t used = st->pool->size() / kS;
  pool_ = std::make_shared<core::SamplePool>((used + spare_slots) * kS);
  std::memcpy(pool_->data(), st->pool->data(), st->pool->size() * sizeof(core::Sample));
  table_ = st->table;
  tiles_ = st->tiles;
  // Spare slots: the ring, and every slot of the copy that no table entry uses.
  std::vector<std::uint8_t> in_use(used + spare_slots, 0);
  for (std::uint32_t e : table_)
    if (!(e & BrickStore::kUniform)) in_use[BrickStore::slot_of(e)] = 1;
  for (std::size_t s = in_use.size(); s-- > 0;)
    if (!in_use[s]) free_.push_back(std::uint32_t(s));
}

void EditFloor::reached(const session::Brush& b, std::vector<std::uint32_t>& out) const {
  out.clear();
  const core::Grid& g = vol_.grid;
  const auto nb = core::brick_counts(g);
  const core::Vec3 c = g.to_index(b.centre_m);
  const double cc[3] = {c.x, c.y, c.z}, s[3] = {g.spacing_m.x, g.spacing_m.y, g.spacing_m.z};
  int lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    const int v0 = std::max(int(std::ceil(cc[a] - b.radius_m / s[a])) - 1, 0);
    const int v1 = std::min(int(std::floor(cc[a] + b.radius_m / s[a])) + 1, g.dims[a] - 1);
    if (v1 < v0) return;
    const int r = plan_.radius[std::size_t(a)];
    lo[a] = std::max(floor_div(v0 - 9 - r + 7, 8), 0);
    hi[a] = std::min(floor_div(v1 + 1 + r, 8), nb[a] - 1);
  }
  for (int z = lo[2]; z <= hi[2]; ++z)
    for (int y = lo[1]; y <= hi[1]; ++y)
      for (int x = lo[0]; x <= hi[0]; ++x)
        out.push_back(std::uint32_t((std::size_t(z) * std::size_t(nb[1]) + std::size_t(y)) * std::size_t(nb[0]) +
                                    std::size_t(x)));
}

std::uint32_t EditFloor::take_slot() {
  while (!retired_.empty() && retired_.front().first + kSlotDelay <= step_) {
    free_.push_back(retired_.front().second);
    retired_.pop_front();
  }
  if (free_.empty()) throw std::runtime_error("edit floor: no spare sample slot left");
  const std::uint32_t s = free_.back();
  free_.pop_back();
  return s;
}

FloorStep EditFloor::apply(const session::Brush& b, std::uint64_t version) {
  FloorStep out;
  ++step_;
  const auto t0 = Clock::now();
  const session::BrushResult br = session::apply_brush_cpu(vol_, b);
  const auto t1 = Clock::now();
  out.brush_ms = ms_between(t0, t1);
  out.dirty = br.dirty.size();
  if (br.dirty.empty()) return out;
  reached(b, reach_);
  sparse::CandidateCpu cpu(vol_, plan_);
  const auto nb = core::brick_counts(vol_.grid);
  core::SampleField::ChangedBox box;
  box.known = true;
  box.lo = vol_.grid.dims;
  for (std::uint32_t id : reach_) {
    // The sparse chain's rule: a brick that is no candidate (its window's range does not
    // straddle) is uniform with that range's tile; a candidate by its exact range.
    const sparse::BrickSelection sel = sparse::select_brick(vol_.grid, vol_.voxels.data(), plan_, iso_, id);
    float tile = 0;
    bool active = false;
    if (!sel.candidate) {
      if (!core::tile_value(sel.lo, sel.hi, iso_, proto_->background, tile))
        throw std::logic_error("edit floor: brick " + std::to_string(id) + " straddles but is no candidate");
    } else {
      active = sparse::is_active(cpu.range(id), iso_, proto_->background, tile);
    }
    const std::uint32_t e = table_[id];
    if (active) {
      const std::uint32_t slot = take_slot();
      cpu.samples(pool_->data() + std::size_t(slot) * kS, proto_->background);
      if (!(e & BrickStore::kUniform)) retired_.push_back({step_, BrickStore::slot_of(e)});
      table_[id] = slot * std::uint32_t(kS);
    } else if (e & BrickStore::kUniform) {
      tiles_[e & ~BrickStore::kUniform] = {tile, 0.f, 0.f, 0.f};
    } else {
      retired_.push_back({step_, BrickStore::slot_of(e)});
      table_[id] = BrickStore::kUniform | std::uint32_t(tiles_.size());
      tiles_.push_back({tile, 0.f, 0.f, 0.f});
    }
    const auto bc = core::brick_coords(id, nb);
    for (int a = 0; a < 3; ++a) {
      box.lo[a] = std::min(box.lo[a], 8 * bc[a]);
      box.hi[a] = std::max(box.hi[a], std::min(8 * bc[a] + 8, vol_.grid.dims[a]));
    }
  }
  out.recomputed = reach_.size();
  const auto t2 = Clock::now();
  out.passes_ms = ms_between(t1, t2);
  auto st = std::make_shared<BrickStore>();
  st->bricks = nb;
  st->format = core::SampleFormat::kFp32;
  st->table = table_;
  st->tiles = tiles_;
  st->pool = pool_;
  st->slot_capacity = pool_->size() / kS;
  if (!st->seal(vol_.grid.dims)) throw std::logic_error("edit floor: the built store does not seal");
  auto f = std::make_shared<core::SampleField>(*proto_);
  f->version = version;
  f->changed = box;
  f->bricks = std::move(st);
  out.snapshot = std::move(f);
  out.snapshot_ms = ms_between(t2, Clock::now());
  return out;
}

}  // namespace isotouch::bench
