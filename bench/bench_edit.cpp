// bench_edit.cpp - `isotouch bench edit`. See bench_edit.h.
#include "isotouch/bench/servo_bench.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/bench/bench_edit.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <random>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <sys/prctl.h>

#include "isotouch/bench/edit_floor.h"
#include "isotouch/session/brush.h"
#include "isotouch/session/edit_session.h"
#include "isotouch/core/field_view.h"
#include "isotouch/io/files.h"
#include "isotouch/servo/hri.h"
#include "isotouch/session/live_session.h"
#include "isotouch/engine/passes.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/io/scene.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/sim/sim_device_io.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/io/volume_io.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace isotouch::bench {
using eval::median;
using run::scene_passes;
using run::scene_sample_format;
using run::SceneSetup;
using run::setup_scene;
using eval::percentile;
using io::load_any_volume;
using io::load_scene;
using io::write_file_atomic;
using io::Scene;
using session::EditEvent;
using session::EditOutcome;
using session::EditSession;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {
/// steady_clock now [ns since its epoch]: the clock of every time point in this benchmark.
std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}
double ms_between(std::int64_t t0_ns, std::int64_t t1_ns) { return double(t1_ns - t0_ns) * 1e-6; }
}  // namespace

// ---------------------------------------------------------------------------------------
// Pure helpers

Spread spread(const std::vector<double>& x) {
  Spread s;
  for (double v : x) s.n += std::isnan(v) ? 0 : 1;
  s.median = median(x);
  s.p99 = percentile(x, 0.99);
  s.max = percentile(x, 1.0);
  return s;
}

Verdict misses_verdict(long missed_edit, long ticks_edit, long missed_idle, long ticks_idle) {
  Verdict v;
  std::ostringstream o;
  o << "servo missed deadlines while editing vs idle";
  if (ticks_edit <= 0 || ticks_idle <= 0) {
    o << ": not measured (a phase had no servo tick); target editing <= idle + 3 sqrt(idle)";
    v.text = o.str();
    return v;
  }
  // The idle count scaled to the editing phase's ticks, and its Poisson allowance.
  const double ref = double(missed_idle) * double(ticks_edit) / double(ticks_idle);
  const double limit = ref + 3.0 * std::sqrt(ref);
  o << std::fixed << std::setprecision(2) << " = " << missed_edit << " in " << ticks_edit << " ticks ("
    << 1e4 * double(missed_edit) / double(ticks_edit) << " per 10,000) against idle " << missed_idle << " in "
    << ticks_idle << " (" << 1e4 * double(missed_idle) / double(ticks_idle) << " per 10,000): target editing <= "
    << ref << " + 3 sqrt(" << ref << ") = " << limit;
  if (ticks_edit < kMinJudgedTicks || ticks_idle < kMinJudgedTicks) {
    o << ", undecided: the target needs >= " << kMinJudgedTicks << " ticks in each phase";
    v.text = o.str();
    return v;
  }
  v.measured = true;
  v.met = double(missed_edit) <= limit;
  o << (v.met ? " met" : " NOT met");
  v.text = o.str();
  return v;
}

Verdict verdict_at_least(const std::string& what, double value, double target, int digits,
                         const std::string& why_missing) {
  Verdict v;
  std::ostringstream o;
  o << std::fixed << std::setprecision(digits);
  if (!std::isfinite(value)) {
    o << what << ": not measured" << (why_missing.empty() ? "" : " (" + why_missing + ")") << "; target >= " << target;
    v.text = o.str();
    return v;
  }
  v.measured = true;
  v.met = value >= target;
  o << what << " = " << value << ": target >= " << target << (v.met ? " met" : " NOT met");
  v.text = o.str();
  return v;
}

std::vector<core::Vec3> surface_points(const core::SampleField& field, const core::Isosurface& iso,
                                       std::size_t count, std::uint32_t seed, const core::Vec3& avoid_m,
                                       double avoid_radius_m) {
  const core::FieldView view(field);
  std::vector<core::Vec3> all;
  if (view.empty() || count == 0) return all;
  const auto& d = field.grid.dims;
  // Interior voxels only: both ends of an edge in [1, n - 2] on every axis.
  auto interior = [&](int x, int y, int z) {
    return x >= 1 && y >= 1 && z >= 1 && x <= d[0] - 2 && y <= d[1] - 2 && z <= d[2] - 2;
  };
  for (int z = 1; z <= d[2] - 2; ++z)
    for (int y = 1; y <= d[1] - 2; ++y)
      for (int x = 1; x <= d[0] - 2; ++x) {
        const double v0 = view.voxel(x, y, z).value;
        if (!std::isfinite(v0)) continue;
        const bool in0 = iso.contains(v0);
        const int step[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        for (const auto& s : step) {
          const int x1 = x + s[0], y1 = y + s[1], z1 = z + s[2];
          if (!interior(x1, y1, z1)) continue;
          const double v1 = view.voxel(x1, y1, z1).value;
          if (!std::isfinite(v1) || iso.contains(v1) == in0 || v1 == v0) continue;
          const double t = std::clamp((iso.tau - v0) / (v1 - v0), 0.0, 1.0);
          const core::Vec3 idx{x + t * s[0], y + t * s[1], z + t * s[2]};
          const core::Vec3 p = field.grid.to_world(idx);
          if (core::norm(p - avoid_m) <= avoid_radius_m) continue;
          all.push_back(p);
        }
      }
  std::mt19937 rng(seed);
  std::shuffle(all.begin(), all.end(), rng);
  if (all.size() > count) all.resize(count);
  return all;
}

std::uint64_t changed_voxels(const float* a, const float* b, std::size_t n) {
  std::uint64_t k = 0;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint32_t ua, ub;
    std::memcpy(&ua, a + i, 4);
    std::memcpy(&ub, b + i, 4);
    k += ua != ub;
  }
  return k;
}

VersionSpy::VersionSpy(servo::Renderer& inner, std::size_t capacity)
    : inner_(inner), capacity_(capacity), seen_(std::make_unique<std::atomic<std::int64_t>[]>(capacity)) {
  for (std::size_t i = 0; i < capacity_; ++i) seen_[i].store(0, std::memory_order_relaxed);  // and prefault
}

servo::HriTick VersionSpy::tick(const core::FieldView& field, const core::Vec3& hip_world_m, double dt_s) {
  ticks_.fetch_add(1, std::memory_order_relaxed);
  const servo::HriTick t = inner_.tick(field, hip_world_m, dt_s);
  if (t.contact) contact_.fetch_add(1, std::memory_order_relaxed);
  return t;
}

servo::HriTick VersionSpy::tick(const core::SampleField& field, const core::Vec3& hip_world_m, double dt_s) {
  if (field.version != last_) {
    last_ = field.version;
    if (field.version < capacity_ && seen_[field.version].load(std::memory_order_relaxed) == 0)
      seen_[field.version].store(now_ns(), std::memory_order_release);
  }
  ticks_.fetch_add(1, std::memory_order_relaxed);
  const servo::HriTick t = inner_.tick(field, hip_world_m, dt_s);  // the wrapped renderer's own path
  if (t.contact) contact_.fetch_add(1, std::memory_order_relaxed);
  return t;
}

std::int64_t VersionSpy::seen_ns(std::uint64_t v) const {
  return v < capacity_ ? seen_[v].load(std::memory_order_acquire) : 0;
}

// ---------------------------------------------------------------------------------------
// The benchmark

namespace {
constexpr double kRadiiMm[] = {2.0, 5.0, 10.0};
constexpr double kSeenTimeoutS = 2.0;  // a servo at >= 1 kHz reads a snapshot long before this
constexpr double kTargetMedianMs = 0.25;  // one tick at 4 kHz
constexpr double kTargetP99Ms = 1.0;

std::string num(double v, int prec = 3) {
  if (!std::isfinite(v)) return "n/a";
  std::ostringstream o;
  o << std::fixed << std::setprecision(prec) << v;
  return o.str();
}
std::string csv_num(double v) {
  if (!std::isfinite(v)) return "";
  std::ostringstream o;
  o << std::setprecision(9) << v;
  return o.str();
}

/// Long-form CSV: section, radius_mm, brush, metric, value, unit.
struct Csv {
  std::ostringstream s;
  Csv() { s << "section,radius_mm,brush,metric,value,unit\n"; }
  void row(const std::string& section, const std::string& radius, const std::string& brush, const std::string& metric,
           const std::string& value, const std::string& unit) {
    s << section << ',' << radius << ',' << brush << ',' << metric << ',' << value << ',' << unit << '\n';
  }
};

/// One timed edit. Times [ms]; NaN where not measured.
struct EditRecord {
  double radius_mm = 0;
  session::BrushKind kind = session::BrushKind::kCarve;
  bool changed = false;           ///< the brush changed some voxel (a snapshot was published)
  bool seen = false;              ///< the servo read the new snapshot within kSeenTimeoutS
  double total_ms = kNaN;         ///< submitted -> first tick reading it
  double brush_ms = kNaN;         ///< BrushResult::wall_ms (GPU: dispatch + download of dirty bricks)
  double brush_gpu_ms = kNaN;     ///< BrushResult::gpu_ms (device timestamps)
  double update_ms = kNaN;        ///< LiveUpdateStats::total_ms, or the dense chain's wall time
  double recompute_ms = kNaN;     ///< LiveUpdateStats::recompute_ms (passes on the recomputed bricks)
  double snapshot_ms = kNaN;      ///< LiveUpdateStats::publish_ms (the new snapshot built)
  double apply_ms = kNaN;         ///< EditOutcome::wall_ms: EditSession::apply, everything included
  double after_publish_ms = kNaN;  ///< EditOutcome::after_publish_ms (publish, undo step, shadow, log): partly off the edit-to-haptics path
  bool on_device = false;         ///< the brush ran on the Vulkan device
  double publish_to_tick_ms = kNaN;  ///< TripleBuffer::publish called -> first tick reading it
  double dirty = kNaN, recomputed = kNaN;  ///< bricks
};

session::Brush make_brush(session::BrushKind k, const core::Vec3& centre, double radius_m,
                         const session::BrushTargets& t) {
  session::Brush b;
  b.kind = k;
  b.centre_m = centre;
  b.radius_m = radius_m;
  // One application moves a full-weight voxel all the way to the target.
  b.strength = std::max(1.0, std::abs(double(t.material) - double(t.empty)));
  b.falloff = 0.5;
  b.targets = t;
  return b;
}

/// Waits (polling, the servo never waits) until the servo has read version `v`: its time
/// [ns] or 0 after the timeout.
std::int64_t wait_seen(const VersionSpy& spy, std::uint64_t v, double timeout_s) {
  const std::int64_t end = now_ns() + std::int64_t(timeout_s * 1e9);
  for (;;) {
    if (const std::int64_t t = spy.seen_ns(v)) return t;
    if (now_ns() > end) return 0;
    std::this_thread::sleep_for(std::chrono::microseconds(20));
  }
}

/// The servo, the renderer and the device of the whole run.
struct Rig {
  servo::TripleBuffer<core::SampleField> published;
  std::unique_ptr<servo::HriRenderer> hri;
  std::unique_ptr<VersionSpy> spy;
  sim::TouchScript script;
  std::unique_ptr<sim::SimDevice> device;
  std::unique_ptr<sim::SimDeviceIO> io;
  double rate_hz = 4000;
  std::string setup_note;  // what the system refused (SCHED_FIFO, pinning, mlock), once
  std::string scheduling;  // what the servo got

  servo::ServoThreadConfig config(std::size_t record_ticks) const {
    servo::ServoThreadConfig c;
    c.rate_hz = rate_hz;
    c.record_ticks = record_ticks;
    return c;
  }
  void note(const servo::ServoThread& s, const std::string& n) {
    if (!n.empty() && setup_note.empty()) setup_note = n;
    scheduling = std::string(s.got_fifo() ? "SCHED_FIFO" : "default scheduler") +
                 (s.pinned_cpu() >= 0 ? ", pinned to CPU " + std::to_string(s.pinned_cpu()) : ", not pinned") +
                 (s.memory_locked() ? ", memory locked" : ", memory not locked");
  }
};

/// Applies `b` through the session (which publishes it), waits for the servo to read it.
EditRecord timed_live_edit(EditSession& session, Rig& rig, const session::Brush& b) {
  EditRecord r;
  r.radius_mm = b.radius_m * 1e3;
  r.kind = b.kind;
  EditEvent ev;
  ev.kind = EditEvent::Kind::kBrush;
  ev.brush = b;
  const std::int64_t t0 = now_ns();
  const EditOutcome oc = session.apply(ev, &rig.published);  // published as soon as it is built
  r.brush_ms = oc.brush.wall_ms;
  r.brush_gpu_ms = oc.brush.gpu_ms >= 0 ? oc.brush.gpu_ms : kNaN;
  r.dirty = double(oc.brush.dirty.size());
  r.on_device = oc.brush.on_device;
  if (!oc.published) return r;
  r.changed = true;
  r.update_ms = oc.update.total_ms;
  r.recompute_ms = oc.update.recompute_ms;
  r.snapshot_ms = oc.update.publish_ms;
  r.apply_ms = oc.wall_ms;
  r.recomputed = double(oc.update.recomputed);
  const std::uint64_t v = session.current()->version;
  const std::int64_t t1 = std::chrono::duration_cast<std::chrono::nanoseconds>(oc.published_at.time_since_epoch()).count();
  r.after_publish_ms = oc.after_publish_ms;
  const std::int64_t ts = wait_seen(*rig.spy, v, kSeenTimeoutS);
  if (ts == 0) return r;
  r.seen = true;
  r.total_ms = ms_between(t0, ts);
  r.publish_to_tick_ms = ms_between(t1, ts);
  return r;
}

/// Figures of one sustained phase (idle or editing).
struct Phase {
  bool editing = false;
  int round = 0;
  double seconds = 0;
  long ticks = 0, missed = 0;
  double err_p99_us = kNaN, err_p999_us = kNaN, err_max_us = kNaN;
  long edits = 0;
  std::uint64_t voxel_changes = 0;
  std::vector<double> edit_to_haptics_ms;  ///< editing: per published edit, submit() to the first tick reading it
  bool replay_equal = true;
};

void period_stats(const servo::ServoThread& s, Phase& p) {
  std::vector<double> e;
  e.reserve(s.period_errors_ns().size());
  for (std::int64_t x : s.period_errors_ns()) e.push_back(std::abs(double(x)) * 1e-3);
  p.err_p99_us = percentile(e, 0.99);
  p.err_p999_us = percentile(e, 0.999);
  p.err_max_us = percentile(e, 1.0);
}

/// Copies the voxels of the brick box of `b` (the only voxels it can change) into `out`.
void copy_box(const engine::Volume& v, const session::BrickRange& r, std::vector<float>& out) {
  out.clear();
  const auto& d = v.grid.dims;
  const int x0 = r.lo[0] * 8, x1 = std::min(r.hi[0] * 8, d[0]);
  for (int z = r.lo[2] * 8; z < std::min(r.hi[2] * 8, d[2]); ++z)
    for (int y = r.lo[1] * 8; y < std::min(r.hi[1] * 8, d[1]); ++y) {
      const std::size_t row = (std::size_t(z) * std::size_t(d[1]) + std::size_t(y)) * std::size_t(d[0]);
      out.insert(out.end(), v.voxels.begin() + std::ptrdiff_t(row + std::size_t(x0)),
                 v.voxels.begin() + std::ptrdiff_t(row + std::size_t(x1)));
    }
}

/// Replays `brushes` on `start` with the CPU reference (bit for bit the GPU brushes:
/// tests/test_brush.cpp), counting voxel changes; `equal`: the result equals `end`.
std::uint64_t replay_count(engine::Volume start, const std::vector<session::Brush>& brushes, const engine::Volume& end,
                           bool& equal) {
  std::uint64_t n = 0;
  std::vector<float> before, after;
  for (const auto& b : brushes) {
    const session::BrickRange r = session::touched_range(start.grid, b);
    if (r.empty()) continue;
    copy_box(start, r, before);
    (void)session::apply_brush_cpu(start, b);
    copy_box(start, r, after);
    n += changed_voxels(before.data(), after.data(), before.size());
  }
  equal = start.voxels.size() == end.voxels.size() &&
          changed_voxels(start.voxels.data(), end.voxels.data(), start.voxels.size()) == 0;
  return n;
}

const char* kind_name(session::BrushKind k) { return session::to_string(k); }

std::string default_scene() { return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "chest.json").string(); }

/// Everything the three measurements share: the scene, the edited session, the servo rig
/// and the edit points. Built once by set_up(); not movable (the rig's triple buffer).
struct Bench {
  const BenchEditOptions& o;
  std::ostream& progress;
  std::string load_before;
  Scene scene;
  core::Isosurface iso;
  session::LiveFieldOptions lo;
  session::BrushTargets targets;
  std::unique_ptr<engine::VulkanContext> ctx_owner;
  engine::VulkanContext* ctx = nullptr;
  engine::VulkanContext* brush_ctx = nullptr;
  std::string device_text;
  engine::Volume original;  ///< the unedited volume (the dense comparison starts from it)
  std::unique_ptr<EditSession> session;
  std::shared_ptr<const core::SampleField> first;
  std::size_t total_bricks = 0;
  Rig rig;
  servo::HriParams hp;
  sim::ScriptParams sp;
  std::vector<core::Vec3> pts;
  std::size_t per_radius = 0;
  double max_r = 0;
  std::mt19937 jitter;
  std::vector<std::string> failures;
  std::uint64_t next_version = 0;  ///< the first snapshot version no phase has used (floor, dense)
  /// Length of each sustained phase [s]: --seconds, lengthened (but with --quick) until the
  /// rounds give each phase kMinJudgedTicks servo ticks (+5 %), what the misses verdict needs.
  double phase_s = 0;

  Bench(const BenchEditOptions& opt, std::ostream& prog) : o(opt), progress(prog), jitter(opt.seed + 17) {}
  Bench(const Bench&) = delete;
  Bench& operator=(const Bench&) = delete;

  core::Vec3 point(std::size_t k) const { return pts[k % pts.size()]; }
  /// Edit i of radius index ri: point (ri * per_radius + i / 2), carve then add.
  session::Brush latency_brush(int ri, int i) const {
    const auto kind = i % 2 == 0 ? session::BrushKind::kCarve : session::BrushKind::kAdd;
    return make_brush(kind, point(std::size_t(ri) * per_radius + std::size_t(i / 2)), kRadiiMm[ri] * 1e-3, targets);
  }
  /// A gap of 1 ms + U[0, 1 period): edits arrive at any phase of the servo tick. The
  /// thread's timer slack is 1 ns meanwhile: with the default 50 us the kernel may defer the
  /// wake-up to coalesce it with the servo's own timer, which wakes just before a tick, so
  /// the edits would arrive at a phase tied to the tick instead of a uniform one.
  void jitter_sleep() {
    const int slack = prctl(PR_GET_TIMERSLACK, 0UL, 0UL, 0UL, 0UL);
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
    std::this_thread::sleep_for(
        std::chrono::microseconds(1000 + long(std::uniform_real_distribution<double>(0, 1e6 / o.rate_hz)(jitter))));
    if (slack > 0) prctl(PR_SET_TIMERSLACK, static_cast<unsigned long>(slack), 0UL, 0UL, 0UL);
  }
};

/// Loads the scene and volume, opens the Vulkan device, builds the first snapshot, the
/// servo rig resting on the surface and the edit points away from it.
void set_up(Bench& b) {
  const BenchEditOptions& o = b.o;
  b.load_before = load_average();
  b.phase_s = o.quick ? o.seconds : std::max(o.seconds, 1.05 * double(kMinJudgedTicks) / (o.rounds * o.rate_hz));
  b.scene = load_scene(o.scene.empty() ? default_scene() : o.scene);
  const Scene& scene = b.scene;
  if (scene.volume_path.empty()) throw std::runtime_error(scene.file + ": bench edit needs a scene with a volume file");
  b.progress << "[bench edit] loading " << scene.volume_path << "\n" << std::flush;
  engine::Volume vol = load_any_volume(scene.volume_path);
  b.iso = core::Isosurface{scene.hri.tau, scene.hri.inside};
  if (!(scene.hri.tau > vol.min_value && scene.hri.tau < vol.max_value))
    throw std::runtime_error(scene.file + ": field 'isovalue': " + num(scene.hri.tau) +
                             " is outside the data range of " + vol.path);

  b.lo.passes = scene_passes(scene);
  b.lo.iso = b.iso;
  b.lo.background = float(b.iso.outside_value(vol.min_value, vol.max_value));
  b.lo.format = scene_sample_format(scene);
  b.targets = session::default_targets(vol, b.iso);

  // Vulkan: brushes and the dense chain on the device when there is one.
  engine::ContextOptions co;
  co.device = o.device;
  auto ctx_r = engine::VulkanContext::create(co);
  if (ctx_r) b.ctx_owner = std::move(*ctx_r.value);
  b.ctx = b.ctx_owner.get();
  b.device_text = b.ctx ? b.ctx->info().name + " (" + b.ctx->info().type + ", " + b.ctx->info().driver + ")" +
                              (b.ctx->info().type == "cpu" ? ": a CPU device (lavapipe), not a GPU" : "")
                        : "none (" + ctx_r.error + ")";
  b.brush_ctx = o.brushes == "gpu" ? b.ctx : nullptr;
  b.original = vol;

  b.progress << "[bench edit] first snapshot (" << (b.brush_ctx ? "GPU" : "CPU") << " brushes)\n" << std::flush;
  b.session = std::make_unique<EditSession>(std::move(vol), b.brush_ctx, b.lo);
  b.first = b.session->current();
  b.total_bricks = b.first->bricks ? b.first->bricks->total_bricks() : 0;

  // The servo: HRI at rate_hz on a simulated device pressing on the surface and resting there.
  Rig& rig = b.rig;
  rig.rate_hz = o.rate_hz;
  b.hp = scene.hri;
  b.hp.rate_hz = o.rate_hz;
  rig.hri = std::make_unique<servo::HriRenderer>(b.hp);
  b.sp = scene.script;
  b.sp.approach_distance_m = std::min(b.sp.approach_distance_m, 0.002);
  b.sp.rest_s = 0;
  b.sp.hold_s = 1e6;  // press, then rest on the surface for the whole run
  rig.script = sim::make_touch_script(*b.first, b.hp, b.sp);
  core::Vec3 p0, v0;
  rig.script.at(0, p0, v0);
  rig.device = std::make_unique<sim::SimDevice>(scene.device, p0);
  rig.io = std::make_unique<sim::SimDeviceIO>(*rig.device, rig.script, 1.0 / o.rate_hz);
  rig.spy = std::make_unique<VersionSpy>(*rig.hri, std::size_t(1) << 20);
  rig.published.publish(b.first);

  // Edit points: surface crossings of the first snapshot, away from the probe.
  b.max_r = kRadiiMm[2] * 1e-3;
  b.per_radius = std::size_t(o.edits_per_radius + 1) / 2;
  const std::size_t want = 3 * b.per_radius + 4096;
  b.pts = surface_points(*b.first, b.iso, want, o.seed, rig.script.contact_point_m, 2.0 * b.max_r);
  if (b.pts.empty()) throw std::runtime_error("no surface crossing away from the probe in " + b.session->volume().path);
}

/// One edit of the floor program [ms]; NaN where not measured.
struct FloorRecord {
  double radius_mm = 0;
  double brush_ms = kNaN;      ///< CPU reference brush (one thread)
  double brush_vk_ms = kNaN;   ///< the same brush on the Vulkan device: one submit, wait, download of the box
  double passes_ms = kNaN, snapshot_ms = kNaN, publish_to_tick_ms = kNaN, total_ms = kNaN;
  double recomputed = kNaN;
};

/// What the floor measured.
struct Floor {
  std::vector<FloorRecord> edits;
  std::string vk = "none";  ///< the Vulkan brush's device, or why there is none
  std::string why_not;      ///< non-empty: the floor could not run (the snapshot is not bricked fp32)
};

/// The floor: the latency phase's edits, in the same order from the same volume, by the
/// smallest program doing their work (bench/edit_floor.h: CPU brush, passes on the reached
/// bricks, a snapshot published, first tick reading it), each right after the product's
/// own edit against the same running servo (so both meet the same machine); the brush also
/// on the Vulkan device alone (one submit: dispatch, wait, download). Its snapshots equal
/// the product's (tests/test_bench_edit.cpp), under versions of their own (from half the
/// spy's capacity).
class FloorRunner {
 public:
  explicit FloorRunner(Bench& b) : b_(b), version_(b.rig.spy->capacity() / 2) {
    try {
      prog_ = std::make_unique<EditFloor>(b.original, *b.first, b.lo.passes, b.iso);
    } catch (const std::invalid_argument& e) {
      floor_.why_not = e.what();
      return;
    }
    if (!b.ctx) return;
    auto r = session::BrushEngine::create(*b.ctx, b.original);
    if (!r) {
      floor_.vk = "none (" + r.error + ")";
      return;
    }
    vk_ = std::move(*r.value);
    vk_mirror_ = b.original;
    floor_.vk = b.ctx->info().name;
  }
  /// Applies `br` (of radius `radius_mm`), publishes, waits for the servo to read it; kept
  /// in the figures when `keep`.
  void edit(const session::Brush& br, double radius_mm, bool keep) {
    if (!prog_) return;
    Rig& rig = b_.rig;
    FloorRecord r;
    r.radius_mm = radius_mm;
    if (vk_) r.brush_vk_ms = vk_->apply(br, &vk_mirror_).wall_ms;
    if (version_ >= rig.spy->capacity()) throw std::runtime_error("floor: snapshot versions past the spy's capacity");
    const std::int64_t t0 = now_ns();
    FloorStep f = prog_->apply(br, version_);
    if (!f.snapshot) return;
    const std::int64_t t1 = now_ns();
    rig.published.publish(std::move(f.snapshot));
    const std::int64_t ts = wait_seen(*rig.spy, version_, kSeenTimeoutS);
    if (ts == 0) b_.failures.push_back("floor: the servo did not read snapshot " + std::to_string(version_));
    ++version_;
    b_.next_version = version_;
    if (!keep || ts == 0) return;
    r.brush_ms = f.brush_ms;
    r.passes_ms = f.passes_ms;
    r.snapshot_ms = f.snapshot_ms;
    r.recomputed = double(f.recomputed);
    r.publish_to_tick_ms = ms_between(t1, ts);
    r.total_ms = ms_between(t0, ts);
    floor_.edits.push_back(r);
  }
  Floor take() { return std::move(floor_); }

 private:
  Bench& b_;
  std::uint64_t version_;
  std::unique_ptr<EditFloor> prog_;
  std::unique_ptr<session::BrushEngine> vk_;
  engine::Volume vk_mirror_;
  Floor floor_;
};

/// What the latency phase measured.
struct Latency {
  std::vector<EditRecord> edits;
  Floor floor;  ///< the same edits by the floor program, interleaved
  long contact_ticks = 0, servo_ticks = 0, missed = 0;
};

/// 1. One edit at a time through the session, each timed to the first tick reading it,
/// each followed by the same edit of the floor program.
Latency measure_latency(Bench& b) {
  Latency l;
  Rig& rig = b.rig;
  EditSession& session = *b.session;
  servo::ServoThread servo(rig.published, *rig.spy, *rig.io, rig.config(0));
  rig.note(servo, servo.start());
  const servo::ScopedOffCpu off(servo.pinned_cpu());  // as a LiveSession's edit thread
  // Let the probe reach the surface (<= 2 s), then warm up (first dispatches, pipelines).
  const std::int64_t until = now_ns() + 2'000'000'000;
  while (rig.spy->contact_ticks() == 0 && now_ns() < until) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  b.progress << "[bench edit] warm-up\n" << std::flush;
  const core::Vec3 warm = b.point(b.pts.size() - 1);
  FloorRunner floor(b);
  for (auto kind : {session::BrushKind::kCarve, session::BrushKind::kAdd}) {
    (void)timed_live_edit(session, rig, make_brush(kind, warm, 5e-3, b.targets));
    floor.edit(make_brush(kind, warm, 5e-3, b.targets), 5, false);
  }
  const long ticks0 = rig.spy->ticks(), contact0 = rig.spy->contact_ticks();
  for (int ri = 0; ri < 3; ++ri) {
    b.progress << "[bench edit] latency: " << b.o.edits_per_radius << " edits of radius " << kRadiiMm[ri] << " mm\n"
               << std::flush;
    for (int i = 0; i < b.o.edits_per_radius; ++i) {
      b.jitter_sleep();
      l.edits.push_back(timed_live_edit(session, rig, b.latency_brush(ri, i)));
      if (l.edits.back().changed && !l.edits.back().seen)
        b.failures.push_back("latency: the servo did not read snapshot " + std::to_string(session.current()->version) +
                             " within " + num(kSeenTimeoutS, 1) + " s");
      b.jitter_sleep();
      floor.edit(b.latency_brush(ri, i), kRadiiMm[ri], true);
    }
  }
  l.servo_ticks = rig.spy->ticks() - ticks0;
  l.contact_ticks = rig.spy->contact_ticks() - contact0;
  servo.stop();
  l.missed = servo.missed_deadlines();
  l.floor = floor.take();
  rig.published.publish(session.current());  // the product's snapshot again (the same content as the floor's last)
  return l;
}

/// One sustained phase on a session::LiveSession: its servo thread, and its edit thread
/// applying what this thread submits, one at a time (edit-to-haptics is an edit's own, not
/// a queue's). Editing: back-to-back 5 mm edits from surface point `next_point` on, which
/// moves past the points used. Returns the phase and the brushes applied (`done`).
Phase sustained_phase(Bench& b, bool editing, int round, std::size_t& next_point, std::vector<session::Brush>& done) {
  Phase ph;
  ph.editing = editing;
  ph.round = round;
  session::LiveSessionConfig lc;
  lc.servo = b.rig.config(std::size_t(b.o.rate_hz * b.phase_s * 1.5) + 64);
  std::atomic<long> applied{0};
  lc.on_applied = [&](const EditEvent& e, const EditOutcome& oc, session::EditSource) {
    if (oc.error.empty() && e.kind == EditEvent::Kind::kBrush) done.push_back(e.brush);
    applied.fetch_add(1, std::memory_order_release);
  };
  session::LiveSession live(*b.session, b.rig.published, *b.rig.spy, *b.rig.io, std::move(lc));
  b.rig.note(*live.servo_thread(), live.start());
  const std::int64_t t0 = now_ns(), t_end = t0 + std::int64_t(b.phase_s * 1e9);
  if (!editing) {
    std::this_thread::sleep_until(Clock::time_point(std::chrono::nanoseconds(t_end)));
  } else {
    long i = 0;
    while (now_ns() < t_end) {
      if (i - applied.load(std::memory_order_acquire) >= 1) {
        std::this_thread::sleep_for(std::chrono::microseconds(50));
        continue;
      }
      const auto kind = i % 2 == 0 ? session::BrushKind::kCarve : session::BrushKind::kAdd;
      EditEvent ev;
      ev.brush = make_brush(kind, b.point(next_point + std::size_t(i / 2)), 5e-3, b.targets);
      if (!live.submit(ev)) throw std::runtime_error("sustained: the live session's edit queue refused an edit");
      ++i;
    }
    next_point += std::size_t(i + 1) / 2;
  }
  ph.seconds = ms_between(t0, now_ns()) * 1e-3;
  live.stop();  // queued edits are dropped (counted); `done` holds what was applied
  const session::LiveStats st = live.stats();
  ph.ticks = st.ticks;
  ph.missed = st.missed_deadlines;
  ph.edit_to_haptics_ms = st.edit_to_haptics_ms;
  period_stats(*live.servo_thread(), ph);
  return ph;
}

/// 2. Idle and editing phases, --rounds times; the edits' voxel changes are counted by
/// replaying them on the CPU reference.
std::vector<Phase> measure_sustained(Bench& b) {
  std::vector<Phase> phases;
  std::size_t next_point = 3 * b.per_radius;
  for (int round = 1; round <= b.o.rounds; ++round)
    for (bool editing : {false, true}) {
      b.progress << "[bench edit] sustained round " << round << ": " << (editing ? "editing" : "idle") << " "
                 << b.phase_s << " s\n"
                 << std::flush;
      std::vector<session::Brush> done;
      std::unique_ptr<engine::Volume> start;
      if (editing) start = std::make_unique<engine::Volume>(b.session->volume());
      Phase ph = sustained_phase(b, editing, round, next_point, done);
      if (editing) {
        b.progress << "[bench edit] counting voxel changes (CPU replay of " << done.size() << " edits)\n" << std::flush;
        ph.edits = long(done.size());
        ph.voxel_changes = replay_count(std::move(*start), done, b.session->volume(), ph.replay_equal);
      }
      phases.push_back(ph);
    }
  return phases;
}

/// What the dense comparison measured.
struct Dense {
  std::vector<EditRecord> edits;
  std::string engine = "none";
};

/// 3. The first latency edits again on the unedited volume, each followed by the whole
/// volume's passes (GPU PassChain, or run_chain_cpu without a device), published densely.
Dense measure_dense(Bench& b) {
  Dense d;
  if (b.o.dense_edits <= 0) return d;
  Rig& rig = b.rig;
  const auto passes = scene_passes(b.scene);
  std::unique_ptr<engine::PassChain> chain;
  std::string chain_why;
  if (b.ctx) {
    auto cr = engine::PassChain::create(*b.ctx, passes);
    if (cr) chain = std::move(*cr.value);
    else chain_why = cr.error;
  }
  d.engine = chain ? "GPU PassChain on " + b.ctx->info().name + ", dense fp32"
                   : "run_chain_cpu (one thread, dense fp32)" + (chain_why.empty() ? "" : ": " + chain_why);
  b.progress << "[bench edit] dense: " << d.engine << "\n" << std::flush;
  session::Sculptor sculptor(b.original, b.brush_ctx);
  std::uint64_t version = std::max(b.session->current()->version + 1, b.next_version);
  servo::ServoThread servo(rig.published, *rig.spy, *rig.io, rig.config(0));
  rig.note(servo, servo.start());
  const servo::ScopedOffCpu off(servo.pinned_cpu());  // as a LiveSession's edit thread
  auto recompute = [&]() {
    engine::ChainOutput c = chain ? chain->run(sculptor.volume()) : engine::run_chain_cpu(sculptor.volume(), passes);
    if (!c.samples) throw std::runtime_error("dense chain: no samples (the pass list has no gradient)");
    auto f = std::make_shared<core::SampleField>(std::move(*c.samples));
    f->background = b.lo.background;
    f->version = version++;
    if (f->version >= rig.spy->capacity()) throw std::runtime_error("dense: snapshot versions past the spy's capacity");
    return std::shared_ptr<const core::SampleField>(std::move(f));
  };
  (void)recompute();  // warm-up
  for (int ri = 0; ri < 3; ++ri) {
    b.progress << "[bench edit] dense: " << b.o.dense_edits << " edits of radius " << kRadiiMm[ri] << " mm\n"
               << std::flush;
    for (int i = 0; i < b.o.dense_edits; ++i) {
      b.jitter_sleep();
      const session::Brush br_in = b.latency_brush(ri, i);
      EditRecord r;
      r.radius_mm = kRadiiMm[ri];
      r.kind = br_in.kind;
      const std::int64_t t0 = now_ns();
      const session::BrushResult br = sculptor.apply(br_in);
      const std::int64_t t1 = now_ns();
      std::shared_ptr<const core::SampleField> f = recompute();
      const std::uint64_t ver = f->version;
      const std::int64_t t2 = now_ns();
      rig.published.publish(std::move(f));
      const std::int64_t ts = wait_seen(*rig.spy, ver, kSeenTimeoutS);
      r.changed = true;
      r.brush_ms = br.wall_ms;
      r.brush_gpu_ms = br.gpu_ms >= 0 ? br.gpu_ms : kNaN;
      r.update_ms = ms_between(t1, t2);
      r.dirty = double(br.dirty.size());
      r.recomputed = double(b.total_bricks);
      if (ts != 0) {
        r.seen = true;
        r.total_ms = ms_between(t0, ts);
        r.publish_to_tick_ms = ms_between(t2, ts);
      } else {
        b.failures.push_back("dense: the servo did not read snapshot " + std::to_string(ver) + " within " +
                             num(kSeenTimeoutS, 1) + " s");
      }
      d.edits.push_back(r);
    }
  }
  servo.stop();
  return d;
}

/// The run's set-up: volume, scene, device, brushes, servo, edit points, machine.
void write_header(std::ostream& out, Bench& b, const Latency& lat) {
  const BenchEditOptions& o = b.o;
  const Scene& scene = b.scene;
  const engine::Volume& v = b.session->volume();
  const core::Isosurface& iso = b.iso;
  const auto& lo = b.lo;
  const auto& first = b.first;
  const auto& targets = b.targets;
  const auto& hp = b.hp;
  const auto& sp = b.sp;
  const Rig& rig = b.rig;
  const std::size_t total_bricks = b.total_bricks;
  const std::string& device_text = b.device_text;
  const long servo_ticks = lat.servo_ticks, contact_ticks = lat.contact_ticks, latency_missed = lat.missed;
  const std::string& load_before = b.load_before;
  const double max_r = b.max_r;
  const auto& pts = b.pts;
  EditSession& session = *b.session;
  const auto& g = v.grid;
  out << "# isotouch bench edit\n\n"
      << "- volume: " << v.path << " (" << g.dims[0] << " x " << g.dims[1] << " x " << g.dims[2] << ", spacing "
      << num(g.spacing_m.x * 1e3) << " x " << num(g.spacing_m.y * 1e3) << " x " << num(g.spacing_m.z * 1e3)
      << " mm), " << total_bricks << " bricks of 8^3; scene " << scene.file << "\n"
      << "- isovalue " << scene.hri.tau << " (inside " << core::to_string(iso.inside) << "), passes";
  for (const auto& p : lo.passes) out << " " << p.label();
  out << ", samples " << scene.engine.samples << "; first snapshot: "
      << (first->bricks ? std::to_string(first->bricks->active_bricks()) : std::string("?")) << " active bricks\n"
      << "- Vulkan device: " << device_text << "\n"
      << "- brushes: "
      << session.sculptor().describe_path()
      << "; material " << targets.material << ", empty " << targets.empty << ", strength |material - empty|, falloff 0.5\n"
      << "- servo: HRI at " << num(o.rate_hz, 0) << " Hz (K " << hp.stiffness_n_per_m << " N/m, plane every "
      << hp.plane_update_period << " ticks) on a simulated device pressing " << num(sp.press_depth_m * 1e3, 1)
      << " mm into the surface at (" << num(rig.script.contact_point_m.x * 1e3, 1) << ", "
      << num(rig.script.contact_point_m.y * 1e3, 1) << ", " << num(rig.script.contact_point_m.z * 1e3, 1)
      << ") mm (grid frame) and resting there; " << rig.scheduling << "; in contact on "
      << num(servo_ticks > 0 ? 100.0 * double(contact_ticks) / double(servo_ticks) : kNaN, 1)
      << " % of the ticks of the latency phase, " << latency_missed << " missed deadlines in that phase\n";
  if (!rig.setup_note.empty()) {
    std::string n = rig.setup_note;
    std::replace(n.begin(), n.end(), '\n', ' ');
    out << "- servo set-up refused: " << n << "\n";
  }
  out << "- edit points: " << pts.size() << " isosurface crossings of the first snapshot (seed " << o.seed
      << "), none within " << num(2 * max_r * 1e3, 0) << " mm of the probe; each point is carved, then added back\n"
      << "- machine: " << std::thread::hardware_concurrency() << " hardware threads (" << cpu_model()
      << "), load average (1, 5, 15 min) " << load_before << " before, " << load_average()
      << " after; the machine is shared: other work slows and spreads every figure\n";
}

/// Medians of the latency table that the dense table and the verdicts use.
struct LatencyFigures {
  double med5 = kNaN, p99_5 = kNaN;
  std::vector<double> live_median = std::vector<double>(3, kNaN);  ///< per radius, all kinds
};

/// Picks `field` of the changed edits of `radius` (and `kind`, -1: all).
template <class F>
std::vector<double> pick(const std::vector<EditRecord>& recs, double radius, int kind, F field) {
  std::vector<double> x;
  for (const auto& r : recs)
    if (r.radius_mm == radius && (kind < 0 || int(r.kind) == kind) && r.changed) x.push_back(field(r));
  return x;
}

LatencyFigures write_latency(std::ostream& out, Csv& csv, const Bench& b, const Latency& lat) {
  const BenchEditOptions& o = b.o;
  const std::vector<EditRecord>& live = lat.edits;
  const std::size_t total_bricks = b.total_bricks;
  LatencyFigures fig;
  double& med5 = fig.med5;
  double& p99_5 = fig.p99_5;
  std::vector<double>& live_median = fig.live_median;
  out << "\n## Edit-to-haptics latency (incremental: Sculptor + LiveField)\n\n"
      << "From the edit submitted (EditSession::apply on the engine thread) to the first servo tick that reads the "
         "new snapshot (its steady_clock time, noted by the tick). Medians of the parts; "
      << o.edits_per_radius << " edits per radius, 1 ms + U[0, 1 servo period) apart.\n\n"
      << "| radius [mm] | brush | edits | median [ms] | p99 [ms] | max [ms] | brush [ms] | brush GPU [ms] | update [ms] "
         "| publish-to-tick [ms] | publish-to-tick p99 [ms] | dirty bricks | recomputed bricks |\n"
      << "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (int ri = 0; ri < 3; ++ri) {
    const double rad = kRadiiMm[ri];
    for (int kind : {int(session::BrushKind::kCarve), int(session::BrushKind::kAdd), -1}) {
      const std::string kname = kind < 0 ? "all" : kind_name(session::BrushKind(kind));
      const Spread tot = spread(pick(live, rad, kind, [](const EditRecord& r) { return r.total_ms; }));
      const double brush = median(pick(live, rad, kind, [](const EditRecord& r) { return r.brush_ms; }));
      const double gpu = median(pick(live, rad, kind, [](const EditRecord& r) { return r.brush_gpu_ms; }));
      const double upd = median(pick(live, rad, kind, [](const EditRecord& r) { return r.update_ms; }));
      const Spread ptt = spread(pick(live, rad, kind, [](const EditRecord& r) { return r.publish_to_tick_ms; }));
      const double dirty = median(pick(live, rad, kind, [](const EditRecord& r) { return r.dirty; }));
      const double rec = median(pick(live, rad, kind, [](const EditRecord& r) { return r.recomputed; }));
      out << "| " << num(rad, 0) << " | " << kname << " | " << tot.n << " | " << num(tot.median) << " | "
          << num(tot.p99) << " | " << num(tot.max) << " | " << num(brush) << " | " << num(gpu) << " | " << num(upd)
          << " | " << num(ptt.median) << " | " << num(ptt.p99) << " | " << num(dirty, 0) << " | " << num(rec, 0)
          << " |\n";
      const std::string rs = num(rad, 0);
      csv.row("latency", rs, kname, "edits", std::to_string(tot.n), "");
      csv.row("latency", rs, kname, "median_ms", csv_num(tot.median), "ms");
      csv.row("latency", rs, kname, "p99_ms", csv_num(tot.p99), "ms");
      csv.row("latency", rs, kname, "max_ms", csv_num(tot.max), "ms");
      csv.row("latency", rs, kname, "brush_median_ms", csv_num(brush), "ms");
      csv.row("latency", rs, kname, "brush_gpu_median_ms", csv_num(gpu), "ms");
      csv.row("latency", rs, kname, "update_median_ms", csv_num(upd), "ms");
      csv.row("latency", rs, kname, "publish_to_tick_median_ms", csv_num(ptt.median), "ms");
      csv.row("latency", rs, kname, "publish_to_tick_p99_ms", csv_num(ptt.p99), "ms");
      csv.row("latency", rs, kname, "dirty_bricks_median", csv_num(dirty), "");
      csv.row("latency", rs, kname, "recomputed_bricks_median", csv_num(rec), "");
      if (kind < 0) {
        live_median[std::size_t(ri)] = tot.median;
        if (rad == 5.0) {
          med5 = tot.median;
          p99_5 = tot.p99;
        }
      }
    }
  }
  std::size_t unchanged = 0;
  for (const auto& r : live) unchanged += r.changed ? 0 : 1;
  csv.row("latency", "", "all", "edits_changing_nothing", std::to_string(unchanged), "");
  out << "\nedits: those that changed some voxel (" << unchanged << " of " << live.size()
      << " changed none, published nothing and are left out). "
      << "brush: BrushResult::wall_ms (GPU: dispatch, wait, download of the dirty bricks, undo backup); brush GPU: "
         "device timestamps; update: LiveField::update (passes on the recomputed bricks, the new snapshot); "
         "publish-to-tick: TripleBuffer::publish to the first tick reading it (at most one servo period plus "
         "scheduling delay). recomputed bricks = "
      << total_bricks << " means a full recompute.\n";

  return fig;
}

/// One figure of a table row: its CSV metric (unit ms when it ends in "_ms") and value.
struct Cell {
  const char* metric;
  double value;
  int digits = 3;
};

/// "| radius | edits | median | p99 | cells... |", and the same as CSV rows of `section`.
void table_row(std::ostream& out, Csv& csv, const std::string& section, double radius_mm, const Spread& tot,
               const std::vector<Cell>& cells) {
  const std::string rs = num(radius_mm, 0);
  out << "| " << rs << " | " << tot.n << " | " << num(tot.median) << " | " << num(tot.p99) << " |";
  csv.row(section, rs, "all", "edits", std::to_string(tot.n), "");
  csv.row(section, rs, "all", "median_ms", csv_num(tot.median), "ms");
  csv.row(section, rs, "all", "p99_ms", csv_num(tot.p99), "ms");
  for (const Cell& c : cells) {
    out << " " << num(c.value, c.digits) << " |";
    const std::string m = c.metric;
    csv.row(section, rs, "all", m, csv_num(c.value), m.size() > 3 && m.ends_with("_ms") ? "ms" : "");
  }
  out << "\n";
}

/// Picks `field` of the floor's edits of `radius`.
template <class F>
std::vector<double> pick_floor(const std::vector<FloorRecord>& recs, double radius, F field) {
  std::vector<double> x;
  for (const auto& r : recs)
    if (r.radius_mm == radius) x.push_back(field(r));
  return x;
}

/// The floor's table, and the 5 mm stages of the product beside the floor's. Returns the
/// floor's 5 mm median [ms] (NaN if not measured).
double write_floor(std::ostream& out, Csv& csv, const Bench& b, const Floor& fl, const Latency& lat) {
  out << "\n## Floor: the smallest program doing the same work (same run, same servo)\n\n";
  if (!fl.why_not.empty()) {
    out << "Not measured: " << fl.why_not << ".\n";
    return kNaN;
  }
  out << "The same edits in the same order from the same volume, each right after the product's own edit against "
         "the same servo (bench/edit_floor.h): the CPU reference brush on "
         "the touched bricks of its own copy, the passes (selection, exact range, samples: run_sparse_cpu's per-brick "
         "code) on every brick the brush's voxel box reaches, a new snapshot (table and tiles copied, new slots "
         "written, the rest shared), published into the same triple buffer and read by the same servo; no undo, no "
         "shadow copy, no candidate bookkeeping. Vulkan brush: the same brush on "
      << fl.vk << " alone (one submit: dispatch, wait, download of the touched box), not part of the floor's total.\n\n"
      << "| radius [mm] | edits | median [ms] | p99 [ms] | brush CPU [ms] | brush Vulkan, one submit [ms] | passes [ms] "
         "| snapshot [ms] | publish-to-tick [ms] | recomputed bricks |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  double floor5 = kNaN;
  for (double rad : kRadiiMm) {
    const Spread tot = spread(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.total_ms; }));
    const double br = median(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.brush_ms; }));
    const double vk = median(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.brush_vk_ms; }));
    const double pa = median(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.passes_ms; }));
    const double sn = median(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.snapshot_ms; }));
    const double pt = median(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.publish_to_tick_ms; }));
    const double rc = median(pick_floor(fl.edits, rad, [](const FloorRecord& r) { return r.recomputed; }));
    table_row(out, csv, "floor", rad, tot,
              {{"brush_cpu_median_ms", br}, {"brush_vulkan_median_ms", vk}, {"passes_median_ms", pa},
               {"snapshot_median_ms", sn}, {"publish_to_tick_median_ms", pt}, {"recomputed_bricks_median", rc, 0}});
    if (rad == 5.0) floor5 = tot.median;
  }
  // 5 mm, stage by stage: the product's parts beside the floor's.
  auto prod = [&](auto f) { return median(pick(lat.edits, 5.0, -1, f)); };
  auto flo = [&](auto f) { return median(pick_floor(fl.edits, 5.0, f)); };
  const double p_brush = prod([](const EditRecord& r) { return r.brush_ms; });
  const double p_rec = prod([](const EditRecord& r) { return r.recompute_ms; });
  const double p_snap = prod([](const EditRecord& r) { return r.snapshot_ms; });
  const double p_rest =
      prod([](const EditRecord& r) { return r.apply_ms - r.brush_ms - r.update_ms - r.after_publish_ms; });
  const double p_after = prod([](const EditRecord& r) { return r.after_publish_ms; });
  const double p_ptt = prod([](const EditRecord& r) { return r.publish_to_tick_ms; });
  const double p_tot = prod([](const EditRecord& r) { return r.total_ms; });
  std::size_t on_device5 = 0, n5 = 0;
  for (const EditRecord& r : lat.edits)
    if (r.radius_mm == 5.0 && r.changed) {
      ++n5;
      on_device5 += r.on_device ? 1 : 0;
    }
  out << "\n5 mm edits, stage by stage (medians of each stage, so they need not add up to the total's median):\n\n"
      << "| stage | product [ms] | floor [ms] |\n|---|---:|---:|\n"
      << "| brush | " << num(p_brush) << " | " << num(flo([](const FloorRecord& r) { return r.brush_ms; })) << " |\n"
      << "| passes on the recomputed bricks | " << num(p_rec) << " | "
      << num(flo([](const FloorRecord& r) { return r.passes_ms; })) << " |\n"
      << "| snapshot built | " << num(p_snap) << " | " << num(flo([](const FloorRecord& r) { return r.snapshot_ms; }))
      << " |\n"
      << "| rest of EditSession::apply before publishing (touched bricks, checks, the hook) | " << num(p_rest) << " | - |\n"
      << "| publish to the first tick reading it | " << num(p_ptt) << " | "
      << num(flo([](const FloorRecord& r) { return r.publish_to_tick_ms; })) << " |\n"
      << "| (apply() from publishing on: the publish, then the undo step, shadow copy and log, off this path) | (" << num(p_after) << ") | - |\n"
      << "| **edit to haptics** (target <= 0.250) | **" << num(p_tot) << "** | **" << num(floor5) << "** |\n"
      << "\nPath of the product's brushes: " << b.session->sculptor().describe_path() << "; 5 mm brushes on the device: "
      << on_device5 << " of " << n5 << ". Snapshot updates: " << b.session->live().describe() << ".\n"
      << "At " << num(b.o.rate_hz, 0) << " Hz a snapshot published at a uniformly random phase waits "
      << num(0.5e3 / b.o.rate_hz) << " ms for the next tick on average: the floor of publish-to-tick.\n";
  return floor5;
}

void write_dense(std::ostream& out, Csv& csv, const Bench& b, const Dense& d, const LatencyFigures& fig) {
  const BenchEditOptions& o = b.o;
  const std::vector<EditRecord>& dense = d.edits;
  const std::string& dense_engine = d.engine;
  const std::vector<double>& live_median = fig.live_median;
  out << "\n## The same edits with a dense full recompute\n\n"
      << "Engine: " << dense_engine << "; the whole volume's passes again after each brush, published as a dense "
      << "snapshot; " << o.dense_edits << " edits per radius (the first ones of the latency series, on the unedited "
      << "volume).\n\n"
      << "| radius [mm] | edits | median [ms] | p99 [ms] | brush [ms] | dense recompute [ms] | publish-to-tick [ms] | "
         "dense / incremental (medians) |\n|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (int ri = 0; ri < 3; ++ri) {
    const double rad = kRadiiMm[ri];
    const Spread tot = spread(pick(dense, rad, -1, [](const EditRecord& r) { return r.total_ms; }));
    const double brush = median(pick(dense, rad, -1, [](const EditRecord& r) { return r.brush_ms; }));
    const double upd = median(pick(dense, rad, -1, [](const EditRecord& r) { return r.update_ms; }));
    const double ptt = median(pick(dense, rad, -1, [](const EditRecord& r) { return r.publish_to_tick_ms; }));
    const double q = ratio(tot.median, live_median[std::size_t(ri)]);
    table_row(out, csv, "dense", rad, tot,
              {{"brush_median_ms", brush}, {"recompute_median_ms", upd}, {"publish_to_tick_median_ms", ptt},
               {"dense_over_incremental", q, 1}});
  }
}

/// The editing phases taken together, for the verdicts.
struct SustainedFigures {
  std::vector<double> ed_e2h;
  long ed_missed = 0, ed_ticks = 0, id_missed = 0, id_ticks = 0;
  double rate = kNaN;
};

SustainedFigures write_sustained(std::ostream& out, Csv& csv, const Bench& b, const std::vector<Phase>& phases) {
  const BenchEditOptions& o = b.o;
  SustainedFigures fig;
  std::vector<double>& ed_e2h = fig.ed_e2h;
  long &ed_missed = fig.ed_missed, &ed_ticks = fig.ed_ticks, &id_missed = fig.id_missed, &id_ticks = fig.id_ticks;
  out << "\n## Sustained 5 mm edits while the servo runs at " << num(o.rate_hz, 0) << " Hz\n\n"
      << "Back-to-back 5 mm edits (carve, add, at new surface points) for " << num(b.phase_s, 2) << " s, against the servo "
      << "with the engine idle for as long, in this process, both on a session::LiveSession (the servo thread, and "
         "the edit thread applying what the bench submits, one edit in flight: the next is submitted when the last was applied); edit-to-haptics from submit() to "
         "the first tick reading the snapshot; voxel changes counted by replaying the same "
         "edits on the CPU reference afterwards (a voxel changed twice counts twice).\n\n"
      << "| phase | round | length [s] | edits | edits/s | edit-to-haptics median [ms] | p99 [ms] | voxel changes | "
         "voxel changes/s | servo ticks | missed | missed per 10,000 | abs period error p99 [us] | p99.9 [us] | max [us] |\n"
      << "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  long ed_edits = 0;
  double ed_seconds = 0;
  std::uint64_t ed_vox = 0;
  bool replay_ok = true;
  for (const Phase& p : phases) {
    const std::string name = p.editing ? "editing" : "idle";
    out << "| " << name << " | " << p.round << " | " << num(p.seconds, 2) << " | "
        << (p.editing ? std::to_string(p.edits) : "-") << " | "
        << (p.editing ? num(double(p.edits) / p.seconds, 1) : "-") << " | "
        << (p.editing ? num(percentile(p.edit_to_haptics_ms, 0.5), 3) : "-") << " | "
        << (p.editing ? num(percentile(p.edit_to_haptics_ms, 0.99), 3) : "-") << " | "
        << (p.editing ? std::to_string(p.voxel_changes) : "-") << " | "
        << (p.editing ? num(double(p.voxel_changes) / p.seconds, 0) : "-") << " | " << p.ticks << " | " << p.missed
        << " | " << num(p.ticks > 0 ? 1e4 * double(p.missed) / double(p.ticks) : kNaN, 2) << " | "
        << num(p.err_p99_us, 1) << " | " << num(p.err_p999_us, 1) << " | " << num(p.err_max_us, 1) << " |\n";
    const std::string r = std::to_string(p.round);
    csv.row("sustained_" + name, "5", r, "seconds", csv_num(p.seconds), "s");
    csv.row("sustained_" + name, "5", r, "servo_ticks", std::to_string(p.ticks), "");
    csv.row("sustained_" + name, "5", r, "missed_deadlines", std::to_string(p.missed), "");
    csv.row("sustained_" + name, "5", r, "period_err_p99_us", csv_num(p.err_p99_us), "us");
    csv.row("sustained_" + name, "5", r, "period_err_p999_us", csv_num(p.err_p999_us), "us");
    if (p.editing) {
      csv.row("sustained_editing", "5", r, "edits", std::to_string(p.edits), "");
      csv.row("sustained_editing", "5", r, "edits_per_s", csv_num(double(p.edits) / p.seconds), "1/s");
      csv.row("sustained_editing", "5", r, "voxel_changes", std::to_string(p.voxel_changes), "");
      csv.row("sustained_editing", "5", r, "voxel_changes_per_s", csv_num(double(p.voxel_changes) / p.seconds), "1/s");
      ed_missed += p.missed;
      ed_ticks += p.ticks;
      ed_edits += p.edits;
      ed_seconds += p.seconds;
      ed_vox += p.voxel_changes;
      ed_e2h.insert(ed_e2h.end(), p.edit_to_haptics_ms.begin(), p.edit_to_haptics_ms.end());
      csv.row("sustained_editing", "5", r, "edit_to_haptics_median_ms", csv_num(percentile(p.edit_to_haptics_ms, 0.5)), "ms");
      replay_ok = replay_ok && p.replay_equal;
    } else {
      id_missed += p.missed;
      id_ticks += p.ticks;
    }
  }
  const double rate = fig.rate = ed_seconds > 0 ? double(ed_edits) / ed_seconds : kNaN;
  out << "\nAll editing rounds: " << num(rate, 1) << " edits/s, "
      << num(ed_seconds > 0 ? double(ed_vox) / ed_seconds : kNaN, 0) << " voxel changes/s. CPU replay "
      << (replay_ok ? "equals the edited volume bit for bit"
                    : "DIFFERS from the edited volume (the GPU brushes and the CPU reference disagree: voxel counts "
                      "are the reference's)")
      << ".\n";
  csv.row("sustained_editing", "5", "all", "edits_per_s", csv_num(rate), "1/s");
  csv.row("sustained_editing", "5", "all", "replay_equal", replay_ok ? "1" : "0", "");
  return fig;
}

/// The verdicts and what failed to run; returns the exit code (1 if something failed).
int write_verdicts(std::ostream& out, Csv& csv, const Bench& b, const Latency& lat, const LatencyFigures& lf,
                   const SustainedFigures& sf, double floor5) {
  const double med5 = lf.med5, p99_5 = lf.p99_5, rate = sf.rate;
  int rc = 0;
  out << "\n## Verdicts (computed from the figures above)\n\n";
  std::vector<Verdict> vs;
  vs.push_back(verdict_at_most("5 mm edit-to-haptics median, one at a time [ms]", med5, kTargetMedianMs, 3,
                               "no 5 mm edit was read by the servo"));
  vs.push_back(verdict_at_most("5 mm edit-to-haptics p99, one at a time [ms]", p99_5, kTargetP99Ms, 3,
                               "no 5 mm edit was read by the servo"));
  vs.push_back(verdict_at_least("sustained 5 mm edits per second", rate, 200.0, 1, "no editing phase"));
  vs.push_back(verdict_at_most("sustained 5 mm edit-to-haptics median (live session) [ms]", percentile(sf.ed_e2h, 0.5),
                               kTargetMedianMs, 3, "no sustained edit was read by the servo"));
  vs.push_back(verdict_at_most("sustained 5 mm edit-to-haptics p99 (live session) [ms]", percentile(sf.ed_e2h, 0.99),
                               kTargetP99Ms, 3, "no sustained edit was read by the servo"));
  vs.push_back(misses_verdict(sf.ed_missed, sf.ed_ticks, sf.id_missed, sf.id_ticks));
  for (const auto& vd : vs) {
    out << "- " << vd.text << "\n";
    csv.row("verdict", "", "", "\"" + vd.text + "\"", vd.measured ? (vd.met ? "1" : "0") : "", "");
  }
  out << "\nFloor (the smallest program doing the same work, measured above in this run): 5 mm median " << num(floor5)
      << " ms, beside the target " << num(kTargetMedianMs) << " ms.\n"
      << "\nTargets: 5 mm edit-to-haptics median <= " << num(kTargetMedianMs) << " ms (one servo period at 4 kHz) one at a time and sustained, p99 <= " << num(kTargetP99Ms)
      << " ms; >= 200 edits/s; servo misses while editing <= idle's (scaled to the same ticks) + 3 sqrt(that), "
         "each phase >= "
      << kMinJudgedTicks << " ticks. A missed target is a result, not a failure (exit 0).\n";
  for (const auto& f : b.failures) {
    out << "\nFAILED: " << f << "\n";
    rc = 1;
  }
  if (lat.servo_ticks <= 0) {
    out << "\nFAILED: the servo made no tick during the latency phase\n";
    rc = 1;
  }
  return rc;
}

/// The whole run; throws on a failure to run (caught by run_bench_edit).
int run(const BenchEditOptions& o, std::ostream& out, std::ostream& progress) {
  Bench b(o, progress);
  set_up(b);
  const Latency lat = measure_latency(b);
  const std::vector<Phase> phases = measure_sustained(b);
  const Dense dense = measure_dense(b);

  Csv csv;
  write_header(out, b, lat);
  const LatencyFigures lf = write_latency(out, csv, b, lat);
  const double floor5 = write_floor(out, csv, b, lat.floor, lat);
  write_dense(out, csv, b, dense, lf);
  const SustainedFigures sf = write_sustained(out, csv, b, phases);
  const int rc = write_verdicts(out, csv, b, lat, lf, sf, floor5);
  if (!o.out_csv.empty()) {
    write_file_atomic(o.out_csv, csv.s.str());
    progress << "[bench edit] wrote " << o.out_csv << "\n";
  }
  return rc;
}
}  // namespace

int run_bench_edit(const BenchEditOptions& options, std::ostream& out, std::ostream& progress) {
  try {
    return run(options, out, progress);
  } catch (const std::exception& e) {
    out << "\nFAILED: bench edit: " << e.what() << "\n";
    progress << "isotouch bench edit: " << e.what() << "\n";
    return 1;
  }
}


}  // namespace isotouch::bench
