// sim_device.h - a simulated point-based haptic device held by an operator's hand.
//
// Device I/O only: it reports an encoder position and takes a force command; force
// rendering lives in hri.h. The end effector is a point mass with viscous damping and
// Coulomb friction, moved by the operator's hand (a spring-damper toward a scripted
// target) and by the rendered force, which the device clips at its force limit and holds
// over each servo period (zero-order hold). Motion is integrated with semi-implicit Euler
// in `substeps` steps per servo period (>= 20 by default), raised automatically to the
// fewest that integrate stably (min_stable_substeps): a light mass on a stiff, damped
// hand otherwise diverges to NaN.
#pragma once
#include "isotouch/sim/servo_names.h"
#include "isotouch/core/vec3.h"

namespace isotouch::sim {

/// Physical parameters of the simulated device and hand (device space, SI units).
struct SimDeviceParams {
  double mass_kg = 0.08;                 ///< end-effector mass m [kg] (Phantom-class)
  double damping_n_s_per_m = 0.01;       ///< device viscous damping b [N s/m]
  double coulomb_friction_n = 0.0;       ///< dry friction of the mechanism [N]
  double encoder_resolution_m = 0.0;     ///< position quantum of the encoders [m]; 0 = ideal
  double force_max_n = 10.0;             ///< actuator saturation F_max [N] (direction kept)
  double hand_stiffness_n_per_m = 300;   ///< operator hand spring [N/m]
  double hand_damping_n_s_per_m = 5;     ///< operator hand damper [N s/m]
  int substeps = 20;                     ///< integration steps per servo period
};

/// Most substeps per servo period step() will use (bounds its cost).
inline constexpr int kMaxSubsteps = 100000;

/// Fewest semi-implicit Euler substeps per period dt_s [s] that integrate the device
/// stably, with a factor-2 margin. Within a substep h the forces acting on the mass m
/// are the hand spring k = hand_stiffness and the dampers c = hand_damping + damping
/// (the rendered force is held over the period, so the servo's K and B do not enter).
/// For x'' = -(c x' + k x)/m the update v+ = v + h F/m, x+ = x + h v+ has the
/// characteristic polynomial z^2 - (2 - a - b) z + (1 - b), a = h^2 k/m, b = h c/m;
/// by Jury's test it is stable iff b < 2 and a + 2b < 4. We require a + 2b <= 2.
/// Returns kMaxSubsteps + 1 when even kMaxSubsteps are too few (or inputs are not
/// positive and finite).
int min_stable_substeps(const SimDeviceParams& p, double dt_s);

/// Smallest mass [kg] that min_stable_substeps integrates within `substeps` per dt_s.
double min_stable_mass_kg(const SimDeviceParams& p, double dt_s, int substeps);

/// Point-mass device. Energies are tracked for passivity measurements.
class SimDevice {
 public:
  SimDevice(const SimDeviceParams& params, const Vec3& start_device_m)
      : p_(params), x_(start_device_m) {}

  /// Encoder reading: end-effector position quantized to encoder_resolution_m, device [m].
  Vec3 position() const;
  /// True end-effector position, device [m] (no quantization; for analysis only).
  Vec3 true_position() const { return x_; }
  /// End-effector velocity, device [m/s].
  Vec3 velocity() const { return v_; }
  void set_state(const Vec3& x, const Vec3& v) { x_ = x; v_ = v; }

  /// The force the servo commands for the next period [N], device axes. Non-finite
  /// commands are refused (zero force, counted); |F| is clipped at force_max_n.
  void command_force(const Vec3& force_n);
  /// Force actually applied after the device's own checks and saturation [N].
  const Vec3& applied_force() const { return f_cmd_; }

  /// Advance by dt [s] with the hand pulling toward `hand_target_m` (device [m]),
  /// which moves with velocity `hand_target_v` [m/s]. Uses
  /// max(params.substeps, min_stable_substeps(params, dt)) substeps, at most kMaxSubsteps.
  void step(double dt, const Vec3& hand_target_m, const Vec3& hand_target_v);

  /// Force the hand applies at the current state [N].
  Vec3 hand_force(const Vec3& hand_target_m, const Vec3& hand_target_v) const {
    return (hand_target_m - x_) * p_.hand_stiffness_n_per_m +
           (hand_target_v - v_) * p_.hand_damping_n_s_per_m;
  }

  /// Work the rendered force has done on the end effector since construction [J]
  /// (positive: the virtual environment handed energy to the device and hand).
  double rendered_work_j() const { return rendered_work_; }
  /// Energy dissipated by the device's viscous damping b since construction [J].
  double damping_dissipated_j() const { return damping_loss_; }
  long refused_commands() const { return refused_; }
  long saturated_commands() const { return saturated_; }
  const SimDeviceParams& params() const { return p_; }
  /// Substeps the last step() used (0 before the first).
  int substeps_used() const { return substeps_used_; }

 private:
  SimDeviceParams p_;
  Vec3 x_;
  Vec3 v_;
  Vec3 f_cmd_;
  double rendered_work_ = 0;
  double damping_loss_ = 0;
  long refused_ = 0;
  long saturated_ = 0;
  int substeps_used_ = 0;
  double cached_dt_ = -1;
  int cached_steps_ = 0;
};

}  // namespace isotouch::sim
