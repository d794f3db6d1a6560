// sim_device.h - a simulated point-based haptic device held by an operator's hand.
//
// Device I/O only: it reports a position and takes a force command; force rendering
// lives in hri.h. The end effector is a point mass moved by the operator's hand (a
// spring-damper toward a scripted target) and by the rendered force, so the rendered
// force really acts back on the motion.
#pragma once
#include "vec3.h"

namespace isotouch::servo {

/// Physical parameters of the simulated device and hand (device space, SI units).
struct SimDeviceParams {
  double mass_kg = 0.08;                 ///< end-effector mass m [kg] (Phantom-class)
  double damping_n_s_per_m = 0.01;       ///< device viscous damping b [N s/m]
  double hand_stiffness_n_per_m = 300;   ///< operator hand spring [N/m]
  double hand_damping_n_s_per_m = 5;     ///< operator hand damper [N s/m]
  int substeps = 20;                     ///< integration steps per servo period
};

/// Point-mass device. The servo force is held constant over a servo period
/// (zero-order hold); motion is integrated with semi-implicit Euler in `substeps`.
class SimDevice {
 public:
  SimDevice(const SimDeviceParams& params, const Vec3& start_device_m)
      : p_(params), x_(start_device_m) {}

  /// Encoder reading: end-effector position, device [m].
  Vec3 position() const { return x_; }
  /// End-effector velocity, device [m/s].
  Vec3 velocity() const { return v_; }

  /// The force the servo commands for the next period [N], device axes.
  void command_force(const Vec3& force_n) { f_cmd_ = force_n; }

  /// Advance by dt [s] with the hand pulling toward `hand_target_m` (device [m]),
  /// which moves with velocity `hand_target_v` [m/s].
  void step(double dt, const Vec3& hand_target_m, const Vec3& hand_target_v);

  /// Force the hand applies at the current state [N].
  Vec3 hand_force(const Vec3& hand_target_m, const Vec3& hand_target_v) const {
    return (hand_target_m - x_) * p_.hand_stiffness_n_per_m +
           (hand_target_v - v_) * p_.hand_damping_n_s_per_m;
  }

 private:
  SimDeviceParams p_;
  Vec3 x_;
  Vec3 v_;
  Vec3 f_cmd_;
};

}  // namespace isotouch::servo
