// device_io.h - the device side of the servo loop (HAPI: updateDeviceValues / sendOutput).
#pragma once
#include "vec3.h"

namespace isotouch::servo {

/// A haptic device as the servo thread sees it. Both calls happen once per tick on the
/// servo thread and must not allocate, lock or block.
class HapticDeviceIO {
 public:
  virtual ~HapticDeviceIO() = default;
  /// End-effector position, device [m].
  virtual Vec3 read_position_m() = 0;
  /// Force to render until the next call [N], device axes. Must accept any finite value
  /// (the device clips at its own limit) and refuse non-finite ones.
  virtual void write_force_n(const Vec3& force_n) = 0;
};

}  // namespace isotouch::servo

// Transitional: SimDeviceIO moved to sim/sim_device_io.h (isotouch::sim). Code that gets it
// through servo_thread.h (apps/bench_cmd.cpp, tests/test_servo_thread.cpp) still sees it
// wherever sim/ is on the include path; include "sim_device_io.h" there and drop this.
#if __has_include("sim_device_io.h")
#include "sim_device_io.h"
#endif
