// live_passivity.h - the time-domain passivity observer and controller on the servo's live
// output stage (servo_thread.cpp): every renderer's force passes it, after the ramp-in and
// before the ForceGate, for every backend. The gate stays the last stage: whatever damping
// the controller adds is clamped and rate-limited like any demand, and the observer books
// the force the gate actually let through (sent()), not the one it asked for.
//
// Clock: the device's own (DeviceReading::device_time_us, unwrapped) where the backend
// reports one (nonzero), else the servo's tick start, standing still while the position
// repeats (a re-read report). A tick that reads the same report again has no period: its
// work is booked (zero, the position did not move) and no damping is added.
//
// Restarts: the observer forgets its last position, its clock and its choice of clock (its
// energy so far is kept in the totals) on a reconnection (restart()) and when the device's
// clock goes back, reads 0 (a reset device, or one that lost its clock: the servo's clock
// takes over until a clock is reported again) or jumps ahead of the servo's by more than
// kClockJumpNs (0.1 s). Without it a device
// reporting 0 after a reset freezes the clock, and with no period there is no damping.
//
// Scope (measured in simulation, docs/haptics.md): this is the one-port rule of
// Hannaford-Ryu at the servo's end. It makes a sampled wall passive where the servo's force
// reaches the device within its own tick (report devices, vendor SDK threads); it does not
// make a link with delay passive (igtl, serve's stream): there the damping arrives a round
// trip late, and the controller has to run at the device end (sim/linked_contact.h).
// Allocation-free, lock-free, no syscall; stats() is safe from any thread.
#pragma once
#include "isotouch/servo/core_names.h"
#include <atomic>
#include <cstdint>
#include <string>

#include "isotouch/core/vec3.h"
#include "isotouch/servo/port_passivity.h"

namespace isotouch::servo {

/// What the live stage's observer measured since the servo started (device frame, SI).
struct PassivityStats {
  bool control = false;       ///< the controller was on (else observe only)
  bool device_clock = false;  ///< the device's clock was used (else the servo's)
  double energy_in_j = 0;     ///< energy the user put into the port [J] (>= 0)
  double energy_out_j = 0;    ///< energy the sent force handed the user [J] (>= 0)
  double dissipated_j = 0;    ///< work of the added damping against the motion [J]
  long active_ticks = 0;      ///< ticks the controller added damping
  long restarts = 0;          ///< observer restarts: reconnections, device clock resets or jumps
};

/// One line for a log or a panel: "controller on (device clock): in 12.3 mJ, out 4.56 mJ,
/// dissipated 0.789 mJ; damping added on 12 ticks, 0 restarts" (energies in mJ, 3
/// significant digits; "observer only" when the controller is off; "servo clock" when the
/// device reports none). Not for the servo tick (it allocates).
std::string describe(const PassivityStats& s);

/// A device clock step this much past the servo's own over the same ticks is a jump [ns].
inline constexpr std::int64_t kClockJumpNs = 100000000;

class LivePassivity {
 public:
  /// Forget everything and start afresh (ServoThread::start(), before the thread).
  /// @param control add damping (else observe only); @param alpha_max_n_s_per_m largest
  /// added damping [N s/m]; @param force_limit_n |F| clip [N] (finite, > 0);
  /// @param hold_s how long a force is held on the device [s] (the servo's period): the
  /// damping's cap is taken over at least it (PortPassivity's hold_period_s).
  /// @throws std::invalid_argument naming the setting and its value (PortPassivity).
  void start(bool control, double alpha_max_n_s_per_m, double force_limit_n, double hold_s);
  /// A good tick: the device reported `x_m` (device frame [m]) with its clock
  /// `device_time_us` (0: none), the servo's tick started at `servo_ns` [ns]; `demand_n` is
  /// the ramped renderer force [N]. Returns the demand with the damping added [N]; a
  /// non-finite demand unchanged (the gate turns it into an exact zero at once).
  Vec3 step(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m, const Vec3& demand_n);
  /// A tick that bypasses the controller (the ramp's first tick, a renderer fault, a pause, a
  /// stale report; the servo sends its own force, given to sent() next): the work the held
  /// force did over the motion to `x_m` is booked, so that no period of it is lost.
  void skip(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m);
  /// What was actually written this tick [N] (the gate's output; zero on a held tick).
  void sent(const Vec3& f_n);
  /// The device reconnected: start the observer afresh at its next tick (counted). Out of
  /// line and cold: kept off the every-tick path's code.
  [[gnu::noinline, gnu::cold]] void restart();
  /// The clock the last step() used [s] since the first good tick (servo thread).
  double last_clock_s() const { return last_clock_s_; }
  /// The figures so far (any thread; each figure consistent on its own).
  PassivityStats stats() const;

 private:
  double clock_s(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m);
  bool clock_broke(std::int64_t servo_ns, std::uint32_t device_time_us) const;
  void publish();
  PortPassivity pc_{false, 0.0, 1.0};
  bool control_ = false;
  bool started_ = false;        // a clock was chosen (the first good tick)
  bool device_clock_ = false;
  std::uint32_t last_us_ = 0;   // the device clock's last raw value (it wraps)
  std::int64_t device_us_ = 0;  // unwrapped device time since the first tick [us]
  std::int64_t first_ns_ = 0;   // the servo's first good tick [ns]
  std::int64_t last_ns_ = 0;    // the servo's tick that last read the device clock [ns]
  double servo_t_ = 0;          // servo clock: the tick that last read a new position [s]
  Vec3 last_x_;                 // the last position read (device frame [m])
  double last_clock_s_ = 0;
  PassivityStats banked_;       // the figures of the observers before the last restart
  std::atomic<double> e_in_{0}, e_out_{0}, dissipated_{0};
  std::atomic<long> active_{0}, restarts_{0};
  std::atomic<bool> control_pub_{false}, device_clock_pub_{false};
};

}  // namespace isotouch::servo
