// trace_figures.h - the figures of a run's ticks: tick times, contact forces and their
// steps, the stroke and lift-off, and the VHIP's true distance from the isosurface.
#pragma once
#include <optional>
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

/// The first-order estimate |f - tau| / |grad f| [m] as a distance: itself when finite and at
/// most `bound_m` (the volume's diagonal, farther than any point of the volume is from a
/// surface in it), else nullopt: where |grad f| is near 0 it is no distance at all.
std::optional<double> first_order_as_distance(double estimate_m, double bound_m);

// The trace's figures into `m`: tick times, contact forces and their steps, the stroke and
// lift-off, and the VHIP's surface error (against the edited volume a tick read, with edits).
// Returns how many contact ticks found a surface (true distance; unfiltered data).
std::pair<long, long> trace_figures(const std::vector<sim::TraceRow>& trace, const SceneSetup& setup,
                                    const EditDriver* edits, RunMetrics& m);

}  // namespace isotouch::run
