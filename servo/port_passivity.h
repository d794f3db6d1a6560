// port_passivity.h - time-domain passivity at the device port of a delayed link.
//
// Sources: B. Hannaford and J.-H. Ryu, "Time-domain passivity control of haptic
// interfaces", IEEE Trans. Robotics and Automation 18(1), 2002 (observer and variable
// damper); J.-H. Ryu, J. Artigas and C. Preusche, "A passive bilateral control scheme for
// a teleoperator with time-varying communication delay", Mechatronics 20(7), 2010 (the
// energy split by direction, E_out(k) <= E_ref(k)).
//
// The observer runs where the force is held and the motion is measured: the device end of
// a link, on the device's own clock. It splits the port's energy into E_in (the user
// pushed against the held force: energy into the link and the environment) and E_out (the
// held force did work on the user). The controller adds the damping -alpha v that keeps
// E_out at or below a reference energy: E_in itself (one-port, Hannaford-Ryu: the link and
// the environment behind it together never hand out more than they took in), or, in the
// two-port form, the energy the far side reports it put into the channel (that form also
// needs a controller at the far side, which this class is not).
// Allocation-free, lock-free, no syscall: safe in a device or servo tick.
#pragma once
#include "isotouch/servo/core_names.h"
#include "isotouch/core/vec3.h"

namespace isotouch::servo {

class PortPassivity {
 public:
  /// @param enabled false: observe only. @param alpha_max largest added damping [N s/m];
  /// keep it well below 2 m / T (m the device's mass, T its period): a sampled damper with
  /// alpha T / m > 2 is itself active.
  /// @param force_limit_n forces are clipped here (direction kept) [N].
  /// @param hold_period_s how long the returned force is held [s] (0: the clock's period):
  /// the damping's cap alpha_max / dt is taken over at least it, so that a clock step
  /// shorter than the hold (a jittered device clock faster than the servo) cannot raise the
  /// force per metre of motion past alpha_max / hold, the gain the device's limit is for.
  /// @throws std::invalid_argument naming the setting and its value unless alpha_max is
  /// finite and >= 0, force_limit_n finite and > 0 and hold_period_s finite and >= 0.
  PortPassivity(bool enabled, double alpha_max, double force_limit_n, double hold_period_s = 0);

  /// One tick at device time t_s [s] (device clock; the period is the difference of two
  /// successive t_s), one-port rule: E_out may not exceed E_in, both updated this tick.
  /// @param x position read this tick, device frame [m]
  /// @param f_want force the link delivers this tick [N], device frame
  /// @return the force to hold until the next tick [N], device frame.
  Vec3 step(double t_s, const Vec3& x, const Vec3& f_want) { return tick(t_s, x, f_want, nullptr, enabled_); }
  /// The same with the reference given: E_out may not exceed e_ref_j [J] (two-port form:
  /// the energy the far side reports it put into the channel).
  Vec3 step(double t_s, const Vec3& x, const Vec3& f_want, double e_ref_j) { return tick(t_s, x, f_want, &e_ref_j, enabled_); }
  /// A tick whose force does not come from step() (a later stage sent its own, given to
  /// sent() next): the held force's work over the motion to `x` [m] at t_s [s] is booked,
  /// nothing is damped.
  void observe(double t_s, const Vec3& x) { tick(t_s, x, {}, nullptr, false); }

  /// The force actually held until the next tick was `f_sent` [N], device frame, not the one
  /// step() returned (a later stage clamped or rate-limited it, or sent zero): the next
  /// tick's work is booked with it. The damping's share is scaled down with it.
  void sent(const Vec3& f_sent);

  /// Start afresh: energies, counts, the last position, time and force forgotten.
  void restart() { *this = PortPassivity(enabled_, alpha_max_, f_max_, min_period_s_); }

  /// Energy the user put into the port since the start [J] (>= 0).
  double energy_in_j() const { return e_in_; }
  /// Energy the held force handed the user since the start [J] (>= 0).
  double energy_out_j() const { return e_out_; }
  /// Work the added damping (its share of the held force, after the clip) did against the
  /// user's motion since the start [J]. The damping is set from the last period's motion, so
  /// a tick on which the motion reverses books a negative amount: the sum is not bounded
  /// below by 0 tick by tick.
  double dissipated_j() const { return dissipated_; }
  /// Damping added at the last tick [N s/m]; ticks with alpha > 0 so far.
  double alpha() const { return alpha_; }
  long active_ticks() const { return active_; }
  bool enabled() const { return enabled_; }

 private:
  Vec3 tick(double t_s, const Vec3& x, const Vec3& f_want, const double* e_ref_j, bool control);
  bool enabled_;
  double alpha_max_;
  double f_max_;
  double min_period_s_;  // the shortest period the damping's cap is taken over [s]
  bool started_ = false;
  double prev_t_ = 0;
  Vec3 prev_x_;
  Vec3 prev_f_;
  Vec3 prev_damp_;
  double e_in_ = 0, e_out_ = 0, dissipated_ = 0, alpha_ = 0;
  long active_ = 0;
};

}  // namespace isotouch::servo
