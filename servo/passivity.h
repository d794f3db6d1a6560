// passivity.h - time-domain passivity observer and controller at the device port.
//
// Source: B. Hannaford and J.-H. Ryu, "Time-domain passivity control of haptic
// interfaces", IEEE Trans. Robotics and Automation 18(1), 2002. The observer sums the
// energy that flows into the virtual environment through the device port; the
// controller adds a variable damping force -alpha v whenever the energy predicted after
// this tick would be negative, so the environment never hands out more than it took in.
// Allocation-free, lock-free: safe in the servo tick.
#pragma once
#include "isotouch/servo/core_names.h"
#include "isotouch/core/vec3.h"

namespace isotouch::servo {

class PassivityController {
 public:
  /// @param period_s servo period T [s]; @param enabled false: observe only
  /// @param alpha_max largest damping the controller may add [N s/m]
  /// @param force_limit_n forces are clipped here (direction kept), as the device would
  PassivityController(double period_s, bool enabled, double alpha_max, double force_limit_n)
      : T_(period_s), enabled_(enabled), alpha_max_(alpha_max), f_max_(force_limit_n) {}

  /// One tick. @param x_device position read this tick, device [m]
  /// @param f_env force the renderer wants [N]. @return force to command [N].
  Vec3 step(const Vec3& x_device, const Vec3& f_env);

  /// Energy that has flowed into the virtual environment [J]; passive while >= 0.
  double observed_energy_j() const { return energy_; }
  /// Damping added this tick [N s/m] (0 when the observer saw no deficit).
  double alpha() const { return alpha_; }
  bool enabled() const { return enabled_; }
  void reset() { started_ = false; energy_ = 0; alpha_ = 0; }

 private:
  double T_;
  bool enabled_;
  double alpha_max_;
  double f_max_;
  Vec3 prev_x_;
  Vec3 prev_f_;
  double energy_ = 0;
  double alpha_ = 0;
  bool started_ = false;
};

}  // namespace isotouch::servo
