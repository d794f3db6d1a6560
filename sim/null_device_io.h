// null_device_io.h - a device that stays put and renders nothing: for runs without hardware
// that only need the servo (and for checking the pipeline without motion).
#pragma once
#include "isotouch/sim/servo_names.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/core/vec3.h"

namespace isotouch::sim {

/// Fixed position (device [m]), no buttons; every force is discarded (zero force rendered).
class NullDeviceIO final : public servo::HapticDeviceIO {
 public:
  explicit NullDeviceIO(const Vec3& position_m = {}) : p_(position_m) {}
  Vec3 read_position_m() override { return p_; }
  void write_force_n(const Vec3& f) override { (void)f; }

 private:
  Vec3 p_;
};

}  // namespace isotouch::sim
