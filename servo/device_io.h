// device_io.h - the device side of the servo loop (HAPI: updateDeviceValues / sendOutput).
#pragma once
#include "core_names.h"
#include <cstdint>

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
  /// The buttons as of the last read_position_m() (bit i: button i down); 0 without buttons.
  virtual std::uint32_t buttons() { return 0; }
};

}  // namespace isotouch::servo
