// device_check.h - `isotouch devices --check SPEC`: the first thing to run with a real device.
// It moves nothing (force output is never enabled) while it reads the pose for a while and
// prints it, then asks before it renders a soft virtual wall below where the handle rests.
#pragma once
#include <iosfwd>
#include <string>

namespace isotouch::run {

struct DeviceCheckOptions {
  std::string spec;            ///< openhaptics[:NAME], forcedimension[:INDEX], emu:SOCKET, hid:..., polhem:...
  double read_seconds = 5;     ///< how long the pose is read with force off [s]
  double wall_seconds = 10;    ///< how long the wall is rendered after a "y" [s]
  double wall_stiffness_n_per_m = 100;  ///< soft: a tenth of a Touch's (capped at 0.1 of the device's maximum)
  double wall_depth_m = 0.02;  ///< the wall lies this far below the resting position (device z) [m]
  double wall_force_n = 1.0;   ///< the wall's force never exceeds this [N]
};

/// Runs the check: prints the device, its capabilities, the pose every 0.5 s and the range
/// moved, asks on `in` ("y" renders the wall, anything else ends), and the wall's largest
/// force; then asks again ("y" runs the safety drill at <= 1 N: safety_drill.h).
/// @return 0; 1 if the device cannot be opened, its pose is not finite or stale, or a rule
///         of the drill did not hold.
int check_device(const DeviceCheckOptions& o, std::istream& in, std::ostream& out);

}  // namespace isotouch::run
