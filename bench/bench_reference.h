// bench_reference.h - the standalone pass set `bench engine` measures beside the dense chain:
// the same work as the chain (Gaussian, gradient, brick min/max) in the fastest standalone
// forms measured on lavapipe, each pass its own dispatches, timed in the same run.
//
// - Gaussian: shaders/gauss_axis_x4.comp, three passes (x, y, z): four voxels per invocation,
//   quads through an RGBA32F texel buffer, one vec4 store, 64x1x1 workgroups, the weights
//   specialization constants.
// - gradient: shaders/gradient_whole_x4.comp: the same layout, the x neighbours through an
//   R32F view of the same buffer, four vec4 sample stores.
// - brick min/max (halo 1), two standalone forms, the faster one counted: row ranges then
//   bricks (minmax_rows.comp + minmax_bricks.comp), or row-segment walks then bricks
//   (minmax_segments.comp + minmax_slices.comp).
// Each output is compared bit for bit with the one-thread CPU chain's.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "isotouch/engine/pass_desc.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/engine/volume.h"

namespace isotouch::bench {

/// One standalone pass: median device time [ms] over the runs, and whether its output
/// equalled the CPU chain's bit for bit.
struct StandaloneRow {
  std::string label;
  double ms = 0;
  bool same_bits = false;
};

/// The set's figures; `why` non-empty where it could not run.
struct StandaloneFigures {
  std::string why;
  std::vector<StandaloneRow> rows;  ///< gaussian, gradient, brick min/max (rows), (segments)
  double best_set_ms = 0;           ///< gaussian + gradient + the faster brick min/max [ms]
  std::string best_minmax;          ///< the label of that brick min/max
  /// The best set's time [ms] in each timed run, in run order (gaussian + gradient + that
  /// brick min/max of the same run; NaN in the runs where that form ran untimed, before the
  /// gradient): for ratios paired with runs beside it.
  std::vector<double> set_ms_per_run;
  bool all_same_bits = false;
};

/// The standalone set over one volume: buffers and pipelines made once, one command buffer
/// per run with a timestamp after each pass.
class StandaloneSet {
 public:
  /// @param sigma_mm the chain's Gaussian [mm]. Throws engine::VolumeError where the set
  ///        cannot run on this volume or device (the message says why): rows not of whole
  ///        quads, an axis shorter than the gradient form needs, a kernel radius above
  ///        ISOTOUCH_FUSED_MAX_RADIUS, a binding or texel view too large, device-local memory
  ///        not host-visible.
  StandaloneSet(engine::VulkanContext& ctx, const engine::Volume& v, double sigma_mm);
  ~StandaloneSet();
  StandaloneSet(const StandaloneSet&) = delete;
  StandaloneSet& operator=(const StandaloneSet&) = delete;

  /// One run of every pass, its device times kept if `timed` (an untimed first run takes
  /// the pipelines' first-dispatch work and the buffers' first touch).
  void run(bool timed = true);
  /// Compares the last run's outputs bit for bit with `cpu`, the CPU chain gaussian(sigma_mm)
  /// -> gradient -> brick_minmax(1) on the same volume.
  void check(const engine::ChainOutput& cpu);
  /// Medians of the runs so far.
  StandaloneFigures figures() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotouch::bench
