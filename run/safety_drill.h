// safety_drill.h - `isotouch devices --check`'s safety drill: on the user's own device, at
// <= 1 N, the servo's safety rules exercised and judged from what the servo sent: a step
// demand rises at the gate's rate limit, a renderer stall takes the force off (on a device
// with a thread of its own) and the force comes back through the ramp.
#pragma once
#include <iosfwd>

#include "isotouch/servo/device_io.h"

namespace isotouch::run {

struct SafetyDrillOptions {
  double force_n = 1.0;      ///< the drill's force, up the device's z (capped at the device's peak) [N]
  double push_s = 0.6;       ///< how long it pushes before and after the stall [s]
  int stall_ms = 30;         ///< the renderer's one slow tick [ms]
  double rate_hz = 1000;     ///< servo rate (the device's own loop's, if slower) [Hz]
};

/// Runs the drill on `device` (open, force output off until the servo enables it) and prints
/// one line per rule with "held" or "NOT held", computed from the ticks the servo sent.
/// @return true if every rule held.
bool run_safety_drill(servo::HapticDeviceIO& device, const SafetyDrillOptions& o, std::ostream& out);

}  // namespace isotouch::run
