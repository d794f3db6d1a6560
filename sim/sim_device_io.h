// sim_device_io.h - the simulated device behind the servo thread's device interface.
#pragma once
#include "isotouch/sim/servo_names.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/sim/script.h"
#include "isotouch/sim/sim_device.h"
#include "isotouch/core/vec3.h"
#include "isotouch/servo/workspace.h"

#include <array>
#include <cstdint>
#include <vector>

namespace isotouch::sim {

/// The simulated device driven in real time: each write advances the physics by one servo
/// period with the operator's hand following `script` (world frame, looped), mapped into the
/// device frame by `world_T_device`. Buttons: button 0 is down during each [t0, t1) of
/// `button_down` [s of script time] (not owned; must outlive this).
class SimDeviceIO final : public HapticDeviceIO {
 public:
  SimDeviceIO(SimDevice& device, const TouchScript& script, double period_s,
              const WorkspaceTransform& world_T_device = {},
              const std::vector<std::array<double, 2>>* button_down = nullptr)
      : dev_(device), script_(script), T_(period_s), xf_(world_T_device), buttons_(button_down) {}
  Vec3 read_position_m() override { return dev_.position(); }
  std::uint32_t buttons() override {
    if (!buttons_) return 0;
    for (const auto& iv : *buttons_)
      if (t_ >= iv[0] && t_ < iv[1]) return 1;
    return 0;
  }
  void write_force_n(const Vec3& f) override {
    dev_.command_force(f);
    t_ += T_;
    if (script_.duration_s > 0 && t_ > script_.duration_s) t_ = 0;
    Vec3 p, v;
    script_.at(t_, p, v);
    dev_.step(T_, xf_.to_device(p), v / xf_.scale);
  }
  /// Script time of the next tick [s].
  double script_time_s() const { return t_; }

 private:
  SimDevice& dev_;
  const TouchScript& script_;
  double T_;
  WorkspaceTransform xf_;
  const std::vector<std::array<double, 2>>* buttons_;
  double t_ = 0;
};

}  // namespace isotouch::sim
