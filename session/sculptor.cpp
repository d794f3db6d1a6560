// sculptor.cpp - Sculptor: the volume, the GPU brush engine (or the CPU reference) and the
// undo history kept in step (session/brush.h). Holds no Vulkan code: the GPU brush engine
// comes from the caller's GpuParts (gpu_parts.h; none: every brush on the CPU reference).
#include <string>

#include "isotouch/core/brick_field.h"

#include "isotouch/session/brush.h"

namespace isotouch::session {
using engine::Volume;
using engine::VolumeError;

Sculptor::Sculptor(Volume vol, GpuParts gpu, double history_limit_mib, std::uint64_t max_binding_bytes)
    : vol_(std::move(vol)), history_(history_limit_mib) {
  if (gpu) {
    auto r = gpu.brush_engine(*gpu.ctx, vol_, max_binding_bytes);
    if (!r) throw VolumeError(r.error);
    engine_ = std::move(*r.value);
    history_.set_on_restore([this](const std::vector<std::uint32_t>& ids) { mark_stale(ids); });
    cpu_max_bricks_ = engine_->device_type() == "cpu" ? kCpuBrushMaxBricksOnCpuDevice : kCpuBrushMaxBricksOnGpu;
    const auto nb = core::brick_counts(vol_.grid);
    stale_mark_.assign(std::size_t(nb[0]) * std::size_t(nb[1]) * std::size_t(nb[2]), 0);
    stale_.reserve(stale_mark_.size());  // every brick at most once: mark_stale never allocates
  }
}
Sculptor::~Sculptor() = default;

void Sculptor::begin_stroke() {
  history_.end_stroke(vol_);
  history_.begin_stroke();
}
void Sculptor::end_stroke() { history_.end_stroke(vol_); }

BrushResult Sculptor::apply(const Brush& b) {
  last_own_stroke_ = 0;  // a brush refused below pushed no stroke: a roll-back drops none
  if (std::string e = validate(b); !e.empty()) throw BrushError(e);
  const bool own = !history_.stroke_open();
  if (own) history_.begin_stroke();
  last_own_stroke_ = own ? history_.open_stroke_serial() : 0;
  history_.record(vol_, touched_bricks(vol_.grid, b));
  BrushResult r;
  try {
    r = run_brush(b);
  } catch (...) {
    if (own) history_.end_stroke(vol_);  // a failed application leaves no stroke open
    throw;
  }
  if (own) history_.end_stroke(vol_);
  return r;
}

BrushResult Sculptor::apply_unrecorded(const Brush& b) {
  last_own_stroke_ = 0;
  if (std::string e = validate(b); !e.empty()) throw BrushError(e);
  return run_brush(b);
}

void Sculptor::record_applied(const std::vector<std::uint32_t>& ids, const float* before) {
  const bool own = !history_.stroke_open();
  if (own) history_.begin_stroke();
  try {
    history_.record(vol_.grid, before, ids);
    if (own) history_.end_stroke(vol_);
  } catch (...) {
    // A step with some of its bricks would undo part of the brush: no step, and no older
    // stroke either (undoing one past the brush would give a state that never existed).
    history_.clear();
    if (own) history_.end_stroke(vol_);  // (empty: pushes nothing)
    throw;
  }
}

BrushResult Sculptor::run_brush(const Brush& b) {
  if (engine_ && !cut_ && touched_range(vol_.grid, b).count() > cpu_max_bricks_) {
    sync_device();
    return engine_->apply(b, &vol_);
  }
  BrushResult r = apply_brush_cpu(vol_, b, cut_.get());
  if (engine_) mark_stale(r.dirty);
  return r;
}

void Sculptor::mark_stale(const std::vector<std::uint32_t>& ids) {
  for (std::uint32_t id : ids)
    if (id < stale_mark_.size() && !stale_mark_[id]) {
      stale_mark_[id] = 1;
      stale_.push_back(id);
    }
}

void Sculptor::sync_device() {
  if (!engine_ || stale_.empty()) return;
  engine_->upload_bricks(vol_, stale_);
  for (std::uint32_t id : stale_) stale_mark_[id] = 0;
  stale_.clear();
}

BrushEngine* Sculptor::engine() {
  sync_device();
  return engine_.get();
}

void Sculptor::set_material_cut(std::shared_ptr<const MaterialCut> cut) {
  if (cut)
    if (std::string e = validate(*cut, vol_.voxels.size()); !e.empty()) throw BrushError(vol_.path + ": " + e);
  cut_ = std::move(cut);
}

std::string Sculptor::describe_path() const {
  if (cut_)
    return "CPU reference (one thread), per material (labelled scene: the GPU brush has no label channel)";
  if (!engine_) return "CPU reference (one thread): no Vulkan device given to the brushes";
  return "CPU reference (one thread) for brushes touching <= " + std::to_string(cpu_max_bricks_) +
         " bricks (changed bricks uploaded to the device before its next brush), the Vulkan device (" +
         engine_->device_type() + ") above";
}

void Sculptor::roll_back_apply(const std::vector<std::uint32_t>& ids, const float* voxels) {
  for (std::uint32_t id : ids) copy_brick(vol_, id, voxels);
  if (engine_) mark_stale(ids);
  // By identity, not by depth: the limit may have dropped older strokes as this one was
  // pushed (the depth unchanged), and a stroke that changed nothing was never pushed.
  if (last_own_stroke_ != 0 && history_.newest_stroke_serial() == last_own_stroke_) history_.discard_newest_stroke();
  last_own_stroke_ = 0;
}

std::vector<std::uint32_t> Sculptor::undo() { return history_.undo(vol_); }
std::vector<std::uint32_t> Sculptor::redo() { return history_.redo(vol_); }

}  // namespace isotouch::session
