// sim_device_io.h - the simulated device behind the servo thread's device interface.
#pragma once
#include "device_io.h"
#include "script.h"
#include "sim_device.h"
#include "vec3.h"

namespace isotouch::servo {

/// The simulated device driven in real time: each write advances the physics by one servo
/// period with the operator's hand following `script` (looped), world = device frame.
class SimDeviceIO final : public HapticDeviceIO {
 public:
  SimDeviceIO(SimDevice& device, const TouchScript& script, double period_s)
      : dev_(device), script_(script), T_(period_s) {}
  Vec3 read_position_m() override { return dev_.position(); }
  void write_force_n(const Vec3& f) override {
    dev_.command_force(f);
    t_ += T_;
    if (script_.duration_s > 0 && t_ > script_.duration_s) t_ = 0;
    Vec3 p, v;
    script_.at(t_, p, v);
    dev_.step(T_, p, v);
  }

 private:
  SimDevice& dev_;
  const TouchScript& script_;
  double T_;
  double t_ = 0;
};

}  // namespace isotouch::servo
