// trace_figures.h - the figures of a run's ticks: tick times, contact forces and their
// steps, the stroke and lift-off, and the VHIP's true distance from the isosurface.
#pragma once
#include <utility>
#include <vector>

#include "isotouch/run/edit_driver.h"
#include "isotouch/sim/headless.h"
#include "isotouch/run/run_metrics.h"
#include "isotouch/run/scene_setup.h"

namespace isotouch::run {

/// The angle [deg] between the forces of consecutive contact ticks of one contact. A zero
/// force in contact (a wall that would pull) has no direction: the next nonzero force is
/// compared with the last nonzero one, so a direction that flips through zero counts. A
/// tick out of contact ends the contact.
struct DirectionSteps {
  void add(double t_s, bool contact, const core::Vec3& force_n);
  double rms_deg() const;
  double max_deg = 0;  ///< the largest step [deg]
  double max_t_s = 0;  ///< when it happened [s]
  long pairs = 0;      ///< steps measured

 private:
  double sum2_ = 0;
  core::Vec3 last_{};
  bool have_last_ = false;
};

// The trace's figures into `m`: tick times, contact forces and their steps, the stroke and
// lift-off, and the VHIP's surface error (against the edited volume a tick read, with edits).
// Returns how many contact ticks found a surface (true distance; unfiltered data).
std::pair<long, long> trace_figures(const std::vector<sim::TraceRow>& trace, const SceneSetup& setup,
                                    const EditDriver* edits, RunMetrics& m);

}  // namespace isotouch::run
