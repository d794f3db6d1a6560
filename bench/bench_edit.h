// bench_edit.h - `isotouch bench edit`: edit-to-haptics latency, sustained edit rate and
// servo misses while sculpting the chest CT, against a dense full recompute.
//
// One run, one process, on the scene's volume (default scenes/chest.json: its isovalue,
// inside, passes and sample format):
//  1. latency: carve and add brushes of radius 2, 5 and 10 mm at points on the isosurface
//     of the first snapshot, one at a time; per edit, from the edit submitted (engine
//     thread: Sculptor brush on the GPU when a Vulkan device is there, LiveField update,
//     publish into the servo's TripleBuffer) to the first 4 kHz servo tick that reads the
//     new snapshot (VersionSpy below, wrapped around the HRI renderer of a simulated device
//     resting on the surface); split into brush, update and publish-to-tick;
//  2. sustained: back-to-back 5 mm edits for a few seconds while the servo runs, against an
//     idle servo of the same length in the same process (idle, editing; repeated): edits/s,
//     voxel changes/s (counted by replaying the same edits on the CPU reference afterwards),
//     the servo's missed deadlines and period errors;
//  3. the same edits with a dense full recompute of the whole volume (GPU PassChain, or
//     run_chain_cpu without a device) published the same way: latency and the ratio.
// Then a markdown table and verdicts computed from the measured figures against the issue's
// targets. The pure parts are functions here (tests/test_bench_edit.cpp).
#pragma once
#include <atomic>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/eval/stats.h"
#include "isotouch/bench/bench_engine.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/servo/renderer.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/core/vec3.h"

namespace isotouch::bench {

struct BenchEditOptions {
  std::string scene;          ///< scene file; "" = scenes/chest.json of the source tree
  std::string device;         ///< Vulkan device choice (global --device)
  bool quick = false;         ///< a few seconds (CI): few edits, short phases, one round
  int edits_per_radius = 200; ///< latency edits per radius (half carve, half add)
  int dense_edits = 20;       ///< dense-recompute edits per radius
  double seconds = 3.0;       ///< length of each idle / editing phase of the sustained run [s]
  int rounds = 2;             ///< idle + editing pairs
  double rate_hz = 4000;      ///< servo rate [Hz]
  std::string brushes = "gpu";  ///< "gpu" (CPU reference without a device) or "cpu"
  std::uint32_t seed = 1;     ///< picks the surface points
  std::string out_csv;        ///< also write every figure here (atomic); "" = none
};

/// Runs the benchmark: the report (markdown) on `out`, progress on `progress`.
/// @return 0 (targets met or not), 1 if something failed to run.
int run_bench_edit(const BenchEditOptions& options, std::ostream& out, std::ostream& progress);

// ---------------------------------------------------------------------------------------
// Pure helpers (tests/test_bench_edit.cpp)

/// Median, nearest-rank p99 and max of a sample [same units]; NaN figures if empty.
struct Spread {
  std::size_t n = 0;
  double median = kNaN, p99 = kNaN, max = kNaN;
};
Spread spread(const std::vector<double>& x);

/// Ticks each phase needs before misses_verdict judges.
inline constexpr long kMinJudgedTicks = 20000;
/// "Editing misses no more deadlines than idle": with ref = the idle misses scaled to the
/// editing phase's ticks (missed_idle * ticks_edit / ticks_idle), met when missed_edit <=
/// ref + 3 sqrt(ref) (a Poisson count's 3-sigma allowance). Not measured (undecided, the
/// text says why) if a phase has no tick or fewer than kMinJudgedTicks.
Verdict misses_verdict(long missed_edit, long ticks_edit, long missed_idle, long ticks_idle);

/// "At least `target` per second": met when value >= target; not measured if NaN.
Verdict verdict_at_least(const std::string& what, double value, double target, int digits = 1,
                         const std::string& why_missing = "");

/// Up to `count` points [grid-world m] on the isosurface of `field` (read through
/// core::FieldView, dense or bricked): the crossings of `iso` on the edges between
/// neighbouring voxel centres (x, y and z edges; linear interpolation of the two values),
/// in a pseudo-random order fixed by `seed`; none within `avoid_radius_m` of `avoid_m`
/// (where the servo's probe rests) nor on the outermost voxel layer. Fewer if the field
/// has fewer crossings.
std::vector<core::Vec3> surface_points(const core::SampleField& field, const core::Isosurface& iso,
                                       std::size_t count, std::uint32_t seed, const core::Vec3& avoid_m,
                                       double avoid_radius_m);

/// Voxels whose bits differ between `a` and `b` (same length; NaN == NaN if the bits match).
std::uint64_t changed_voxels(const float* a, const float* b, std::size_t n);

/// A servo-side wrapper that notes, for each snapshot version, the steady_clock time [ns
/// since the clock's epoch] of the first tick that reads it (taken before the wrapped
/// renderer runs), into a preallocated array indexed by version: no allocation, no lock
/// and no syscall in tick() (steady_clock::now is the vDSO). Versions >= capacity are not
/// noted. Also counts ticks and contact ticks. tick() on the servo thread; seen_ns() from
/// any thread (atomics).
class VersionSpy final : public servo::Renderer {
 public:
  VersionSpy(servo::Renderer& inner, std::size_t capacity);
  const char* name() const override { return inner_.name(); }
  void reset() override { inner_.reset(); }
  using servo::Renderer::tick;
  servo::HriTick tick(const core::FieldView& field, const core::Vec3& hip_world_m, double dt_s) override;
  servo::HriTick tick(const core::SampleField& field, const core::Vec3& hip_world_m, double dt_s) override;
  /// When version `v` was first read [ns, steady_clock]; 0 if not (yet) or v >= capacity.
  std::int64_t seen_ns(std::uint64_t v) const;
  std::size_t capacity() const { return capacity_; }
  long ticks() const { return ticks_.load(std::memory_order_relaxed); }
  long contact_ticks() const { return contact_.load(std::memory_order_relaxed); }

 private:
  servo::Renderer& inner_;
  std::size_t capacity_;
  std::unique_ptr<std::atomic<std::int64_t>[]> seen_;
  std::uint64_t last_ = 0;  // servo thread only
  std::atomic<long> ticks_{0}, contact_{0};
};

}  // namespace isotouch::bench
