// passivity_cost.h - what the time-domain passivity controller (servo/port_passivity.h)
// costs per tick, for `bench table1` beside the HRI tick's floor.
#pragma once
#include <vector>

#include "isotouch/core/vec3.h"

namespace isotouch::bench {

/// Median over `reps` runs of the time per PortPassivity::step [ns], each run `ticks`
/// ticks (10^6 for the table) cycling through `hips` (a recorded stroke, device frame [m])
/// at 1 kHz, the force a 800 N/m spring toward the stroke's point 100 ticks behind (a
/// contact's size of force, under the 10 N limit as a rendered force mostly is), controller on.
double port_passivity_ns_per_tick(const std::vector<core::Vec3>& hips, long ticks, int reps);

/// The same for the servo's live stage (servo/live_passivity.h: step() and sent(), with the
/// device's clock unwrapped and the figures published as atomics) [ns per tick].
double live_passivity_ns_per_tick(const std::vector<core::Vec3>& hips, long ticks, int reps);

}  // namespace isotouch::bench
