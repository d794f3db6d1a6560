// brush.h - sculpting brushes on the raw volume, on the GPU with a CPU reference, and the
// C++ API the sculpting app and the scene timeline call.
//
// THE BRUSH MODEL
// Frames: the brush centre is in grid-world [m] (core::Grid: world = origin + spacing *
// index); distances are Euclidean in metres (anisotropic spacing honoured). Values are the
// raw volume's file units (HU for CT, mm for a signed distance, ...).
//
// Weight. For a voxel at index (x, y, z), with c = (centre - origin) / spacing (index
// space, float) and, all in float, in this order:
//     d_a = (float(i_a) - c_a) * spacing_a         [m]
//     r   = sqrt((d_x * d_x + d_y * d_y) + d_z * d_z)
// the voxel is left alone if !(r < radius). Otherwise, with inner = radius (1 - falloff),
//     t = min(max((r - inner) * (1 / (radius - inner)), 0), 1),  w = 1 - (t * t) * (3 - 2 t)
// i.e. w = 1 - smoothstep(inner, radius, r): 1 inside `inner`, falling smoothly to 0 at
// `radius` (falloff in (0, 1]: the soft edge as a fraction of the radius).
//
// Targets. Each brush carries a material value and an empty value (BrushTargets; from
// the scene's isovalue and inside by default_targets): for inside "above" (CT) material is
// high and empty low; for inside "below" (SDF) material is negative and empty positive.
// toward(v, target, step) = v < target ? min(v + step, target) : v > target ? max(v - step,
// target) : v  - moves by at most `step`, never past the target; NaN voxels stay NaN.
//
// Per kind, for a voxel of value v with weight w (per application):
//  - add:    v' = toward(v, material, strength * w)             strength [value units]
//  - carve:  v' = toward(v, empty, strength * w)                strength [value units]
//  - smooth: v' = v + (m - v) * (strength * w), m the mean of the 6 face neighbours of the
//            PRE-EDIT volume (indices clamped to the grid; read from a copy, no
//            read-after-write races), summed ((((xm + xp) + ym) + yp) + zm) + zp, times
//            1/6 (float)                                         strength in [0, 1]
//  - drill:  removal per application  a = rate * dt * max(0, |F| - F_threshold) (double on
//            the host, then float), v' = toward(v, empty, (a * w) / f) with the density
//            factor f = 1 + max(0, (v - empty) * s) * (1 / density_scale), s = sign(material
//            - empty): f grows with the voxel's distance from empty toward material, so bone
//            (1500 HU) is removed more slowly than soft tissue (40 HU); nothing is removed
//            at or below the force threshold; never past the empty value.
//            With a MaterialCut (labelled scenes: Sculptor::set_material_cut), a voxel of
//            material i takes that material's rate (a_i = rate_i * dt * max(0, |F| -
//            F_threshold), in place of the brush's rate) and density_scale (0: the brush's);
//            a voxel of a critical material keeps its value (drill and carve); label 0 takes
//            the brush's own. Such brushes run on the CPU reference only: the shader has no
//            label channel, so a Sculptor with a cut never sends a brush to the device.
//                      rate [value units / (N s)], dt [s], forces [N], density_scale [value units]
// The float constants (c, 1/(radius - inner), amount, ...) are computed once on the host
// (make_brush_push) and shared by the shader and the CPU reference, which do the same float
// operations in the same order (`precise` in GLSL, -ffp-contract=off in C++): bit for bit
// on lavapipe (tests/test_brush.cpp).
//
// Bricks. The voxel-space bounding box of the brush (widened by one voxel against
// rounding, clipped to the grid) touches a box of 8^3 bricks (ids linear, x fastest,
// ceil(dims / 8) per axis: core/brick_field.h); only those are dispatched (one workgroup per
// brick). The dirty set is the bricks in which some voxel's bits changed: what the sparse
// chain must recompute (with its halo) after the edit.
#pragma once
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/session/edit_history.h"
#include "isotouch/session/material_cut.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/shaders/isotouch_shared.h"
#include "isotouch/engine/result.h"
#include "isotouch/engine/volume.h"
#include "isotouch/session/gpu_parts.h"

namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch::session {

enum class BrushKind : std::uint32_t {
  kAdd = ISOTOUCH_BRUSH_ADD,
  kCarve = ISOTOUCH_BRUSH_CARVE,
  kSmooth = ISOTOUCH_BRUSH_SMOOTH,
  kDrill = ISOTOUCH_BRUSH_DRILL,
};
const char* to_string(BrushKind k);

/// Material / empty values [value units] and the drill's density scale.
struct BrushTargets {
  float material = 1.0f;       ///< value of solid material (inside the isosurface)
  float empty = 0.0f;          ///< value of empty space (outside)
  float density_scale = 1.0f;  ///< drill: value distance from empty that doubles the removal time (> 0)
};
/// Targets from the volume's range and the isosurface: material = max(max_value, tau) for
/// inside above, min(min_value, tau) for below; empty = iso.outside_value(min, max) (the far
/// outside end of the range); density_scale = |material - empty| (1 if that is 0).
BrushTargets default_targets(const engine::Volume& vol, const core::Isosurface& iso);

struct Brush {
  BrushKind kind = BrushKind::kAdd;
  core::Vec3 centre_m{0, 0, 0};  ///< grid-world [m]
  double radius_m = 2e-3;        ///< [m], > 0
  double strength = 100.0;       ///< add/carve: [value units] per application; smooth: in [0, 1]
  double falloff = 0.5;          ///< soft edge as a fraction of the radius, in (0, 1]
  BrushTargets targets;
  // Drill only.
  double force_n = 0.0;            ///< |F| the user applies [N]
  double force_threshold_n = 1.0;  ///< nothing is removed at or below this [N]
  double rate = 1000.0;            ///< [value units / (N s)] at density factor 1
  double dt_s = 1e-3;              ///< time of this application [s] (one servo tick: 1 ms)
};

/// Thrown on an invalid brush; what() names the field and the value.
struct BrushError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};
/// Empty if `b` is valid, else the reason naming the field and the value.
std::string validate(const Brush& b);

/// The brush's brick box: bricks [lo, hi) per axis (empty when the brush misses the grid).
struct BrickRange {
  std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
  bool empty() const { return lo[0] >= hi[0] || lo[1] >= hi[1] || lo[2] >= hi[2]; }
  std::size_t count() const {
    return empty() ? 0 : std::size_t(hi[0] - lo[0]) * std::size_t(hi[1] - lo[1]) * std::size_t(hi[2] - lo[2]);
  }
};
/// Bricks the brush's voxel bounding box touches (widened by one voxel, clipped to the grid).
BrickRange touched_range(const core::Grid& grid, const Brush& b);
/// Their ids, ascending.
std::vector<std::uint32_t> touched_bricks(const core::Grid& grid, const Brush& b);

/// Smooth's pre-edit copy: the voxels of the brick range + 1 voxel, clipped: [lo, hi).
struct PreBox {
  std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0};
};
PreBox pre_box(const core::Grid& grid, const BrickRange& r);

/// The push constants of the brush over `grid` (everything but the dispatch's brick
/// origin and windows): shared by the shader and the CPU reference.
gpu::BrushPush make_brush_push(const core::Grid& grid, const Brush& b);

/// What one application did.
struct BrushResult {
  std::vector<std::uint32_t> touched;  ///< bricks dispatched (ascending ids)
  std::vector<std::uint32_t> dirty;    ///< bricks where some voxel changed (ascending ids)
  double wall_ms = 0;                  ///< apply(), everything included
  double gpu_ms = -1;                  ///< GPU: timestamps around the dispatches (-1 if none / CPU)
  std::size_t dispatches = 0;          ///< GPU: dispatches (z-chunks of brick layers)
  bool on_device = false;              ///< ran on the Vulkan device (else the CPU reference)
};

/// The CPU reference: applies `b` to `vol` in place (one thread), same float operations
/// as shaders/brush.comp. With `cut` (labels on vol's grid), the per-material drill above.
/// @throws BrushError on an invalid brush or cut, VolumeError on a bad volume.
BrushResult apply_brush_cpu(engine::Volume& vol, const Brush& b, const MaterialCut* cut = nullptr);

/// The GPU brush engine: keeps the raw volume resident on the device between edits.
/// Volumes up to maxMemoryAllocationSize bytes and 2^32 voxels; each dispatch binds a
/// window of whole slices that fits maxStorageBufferRange (or `max_binding_bytes`), so a
/// large brush is split into z-chunks of brick layers.
///
/// In isotouch::session_gpu (gpu_parts.h): the session library calls it through its virtual
/// functions only, so it links without the Vulkan code.
class BrushEngine {
 public:
  /// Uploads `vol`. @return an error naming the volume and the limit if it does not fit.
  static engine::Result<std::unique_ptr<BrushEngine>> create(engine::VulkanContext& ctx, const engine::Volume& vol,
                                                     std::uint64_t max_binding_bytes = 0);
  virtual ~BrushEngine();
  BrushEngine(const BrushEngine&) = delete;
  BrushEngine& operator=(const BrushEngine&) = delete;

  /// Applies `b` on the device. With `host`, also downloads the dirty bricks into it (it
  /// must be the volume the engine mirrors). @throws BrushError on an invalid brush.
  virtual BrushResult apply(const Brush& b, engine::Volume* host = nullptr);
  /// Copies bricks `ids` of `vol` (the host mirror) to the device (after undo / redo).
  virtual void upload_bricks(const engine::Volume& vol, const std::vector<std::uint32_t>& ids);
  /// The whole device volume (tests, export).
  virtual std::vector<float> download_all();
  virtual const core::Grid& grid() const;
  /// The device's type as Vulkan names it ("cpu" for lavapipe, "discrete-gpu", ...).
  virtual const std::string& device_type() const;

 private:
  struct Impl;
  explicit BrushEngine(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Touched bricks up to which a Sculptor with a Vulkan device applies a brush on the CPU
/// reference (same bits), by device type: one submit + wait + download costs more than the
/// CPU's few microseconds per brick below these (bench edit's floor rows show both).
inline constexpr std::size_t kCpuBrushMaxBricksOnCpuDevice = 256;  ///< lavapipe: the "GPU" is these cores
inline constexpr std::size_t kCpuBrushMaxBricksOnGpu = 16;

/// The API the sculpting app and the scene timeline call: the volume, the GPU engine (or
/// the CPU reference without a context) and the undo history, kept in step.
///
/// Path per brush: with a device, a brush touching at most cpu_max_bricks() bricks runs on
/// the CPU reference on the host volume (bit for bit the shader), and the bricks it changed
/// are marked stale on the device; they are uploaded in one copy before the next device
/// brush, or when engine() is asked for the device copy. Without a device: always the CPU.
class Sculptor {
 public:
  /// @param gpu a VulkanContext* (gpu_parts.h); null: CPU path. @param history_limit_mib
  /// undo memory limit [MiB]. @throws VolumeError if the GPU engine cannot hold the volume.
  Sculptor(engine::Volume vol, GpuParts gpu, double history_limit_mib = 256.0,
           std::uint64_t max_binding_bytes = 0);
  ~Sculptor();
  /// Strokes group applications for undo (e.g. a button press to its release). apply()
  /// outside a stroke is a stroke of its own.
  void begin_stroke();
  void end_stroke();
  /// Applies a brush; returns the touched and dirty bricks (what the passes must redo).
  BrushResult apply(const Brush& b);
  /// apply() without its undo step: the caller records it with record_applied() once the
  /// new snapshot is out (EditSession: off the edit-to-haptics path). @throws as apply().
  BrushResult apply_unrecorded(const Brush& b);
  /// The undo step of the last apply_unrecorded(): the bricks `ids` (at least the ones it
  /// touched) as `before` holds them, a volume of the same grid (x fastest) with their content
  /// before that brush (LiveField::published_voxels() before its update lets it follow the
  /// volume). Outside a stroke it is a stroke of its own, as in apply(); empty `ids` record
  /// nothing (outside a stroke: the redo branch dropped, as by a brush that changed nothing).
  /// @throws std::bad_alloc, or std::out_of_range for an id past the grid's bricks: the whole
  /// history is dropped first (EditHistory::clear; a stroke the caller opened stays open).
  void record_applied(const std::vector<std::uint32_t>& ids, const float* before);
  /// Forgets the whole undo / redo history (EditHistory::clear).
  void drop_history() noexcept { history_.clear(); }
  /// Undo / redo one stroke; return the restored brick ids (dirty for the passes).
  std::vector<std::uint32_t> undo();
  std::vector<std::uint32_t> redo();

  /// Rolls back the last apply() or apply_unrecorded(): the bricks `ids` (at least the ones it touched) copied
  /// back from `voxels`, a volume of the same grid (x fastest) that holds them as they were
  /// before it (LiveField::published_voxels() while its update has not published), and the
  /// undo step it pushed forgotten when it was a stroke of its own that is still the newest
  /// undo step (not one the memory limit dropped, nor one that changed nothing). Call it
  /// before any other edit. Nothing is saved before the brush, and nothing is allocated here.
  void roll_back_apply(const std::vector<std::uint32_t>& ids, const float* voxels);

  const engine::Volume& volume() const { return vol_; }
  const EditHistory& history() const { return history_; }
  bool on_gpu() const { return engine_ != nullptr; }
  /// The GPU copy, first brought up to date with the host volume (null on the CPU path).
  BrushEngine* engine();
  /// Brushes touching at most this many bricks run on the CPU even with a device (0: every
  /// brush on the device). Default: by the device's type (kCpuBrushMaxBricksOn*).
  std::size_t cpu_max_bricks() const { return cpu_max_bricks_; }
  void set_cpu_max_bricks(std::size_t bricks) { cpu_max_bricks_ = bricks; }
  /// Bricks changed on the host that the device copy does not hold yet.
  std::size_t stale_on_device() const { return stale_.size(); }
  /// How apply() picks the path, in words.
  std::string describe_path() const;
  /// Labelled scenes: every later brush removes per material (apply_brush_cpu's `cut`, on
  /// the CPU reference, whatever the device). Null: one material (today's path and bits).
  /// @throws BrushError if `cut` does not fit the volume (validate(MaterialCut)).
  void set_material_cut(std::shared_ptr<const MaterialCut> cut);
  const MaterialCut* material_cut() const { return cut_.get(); }

 private:
  /// The brush on the CPU reference or the device (by its touched bricks), no history.
  BrushResult run_brush(const Brush& b);
  /// Uploads the stale bricks to the device (one copy) and forgets them.
  void sync_device();
  void mark_stale(const std::vector<std::uint32_t>& ids);

  engine::Volume vol_;
  std::unique_ptr<BrushEngine> engine_;
  EditHistory history_;
  std::uint64_t last_own_stroke_ = 0;  ///< the stroke the last apply() opened itself (0: it ran inside one)
  std::size_t cpu_max_bricks_ = 0;
  std::vector<std::uint32_t> stale_;       ///< bricks newer on the host than on the device (unique ids)
  std::vector<std::uint8_t> stale_mark_;   ///< per brick: listed in stale_
  std::shared_ptr<const MaterialCut> cut_; ///< labelled scenes: per-material drilling (CPU path)
};

}  // namespace isotouch::session
