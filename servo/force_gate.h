// force_gate.h - the last stage between every renderer and every device: the force a tick may
// send, whatever the renderer asked for. One rule for every backend (report devices, vendor
// SDKs, OpenIGTLink, serve's TRANSFORM stream), applied by ServoThread.
#pragma once
#include "isotouch/servo/core_names.h"
#include <cmath>
#include <cstdint>

namespace isotouch::servo {

struct DeviceCaps;

/// What the gate allows. Device frame, SI units; INFINITY: no limit of that kind.
struct ForceLimits {
  /// Largest |F| at any instant [N]: min(the scene's force limit, the device's peak).
  double peak_n = INFINITY;
  /// Largest |F(k) - F(k-1)| per second between two sent forces [N/s] (a vector rate: a turn
  /// of the force's direction is a change too). A step from 0 to the limit (a pose after a
  /// network gap, an encoder glitch, a renderer's jump) is spread over peak_n / rate_n_per_s.
  double rate_n_per_s = INFINITY;
  /// Largest RMS |F| the device sustains [N] (OpenHaptics' HD_NOMINAL_MAX_CONTINUOUS_FORCE):
  /// the RMS over continuous_window_s (an exponential window: the motor's heating) is kept
  /// at or below it: while under it any |F| up to the peak passes as long as the tick leaves
  /// the RMS at most continuous_n; once there, |F| is held at continuous_n. (A rate-limited
  /// descent from the peak can pass it by what the descent's ticks add; it then decays.)
  double continuous_n = INFINITY;
  /// The window of the RMS [s] (the motor's thermal time constant). <= 0: no continuous limit.
  double continuous_window_s = 10.0;
  /// The longest time one step's rate allowance counts [s] (the servo's period): a late tick
  /// does not catch up, so no two device frames see more than the rate over a period each.
  double rate_dt_cap_s = INFINITY;
};

/// Without a rate of the device's own, a change of the whole peak takes this long [s]: at
/// 3.3 N, 1650 N/s (a hand at 1 m/s into K = 1650 N/m; faster changes are glitches, not touch).
inline constexpr double kDefaultPeakRiseS = 0.002;

/// The limits for a device with `caps` under a scene whose force limit is `scene_limit_n`
/// [N] (INFINITY: none) and a rate override `rate_n_per_s` (<= 0 or not finite: the device's
/// DeviceCaps::max_force_rate_n_per_s, else peak_n / kDefaultPeakRiseS when the peak is finite).
ForceLimits force_limits(const DeviceCaps& caps, double scene_limit_n, double rate_n_per_s = 0);

/// Why the gate changed a force this tick (bit flags).
enum GateFlag : std::uint8_t {
  kGatePeak = 1,        ///< |F| clamped to peak_n
  kGateContinuous = 2,  ///< |F| capped at continuous_n (the RMS reached it)
  kGateRate = 4,        ///< the change limited to rate_n_per_s x dt
  kGateNonFinite = 8,   ///< a non-finite demand or result: exact zero
};

/// The gate's state between ticks: the last force sent and the RMS window. One per servo
/// thread; step() and zero() allocate nothing, take no lock and make no syscall.
class ForceGate {
 public:
  ForceGate() = default;
  explicit ForceGate(const ForceLimits& limits) : lim_(limits) {}
  const ForceLimits& limits() const { return lim_; }

  /// The force to send for `demand` [N] after `dt_s` [s] since the last step() or zero()
  /// (<= 0 or not finite: taken as 0, no change allowed). In order: a non-finite demand is an
  /// exact zero at once (as zero()); |F| clamped to peak_n (direction kept); capped by the
  /// continuous limit; the change from the last sent force limited to rate x dt. A
  /// non-finite result is an exact zero. `flags` gets GateFlag bits.
  Vec3 step(const Vec3& demand, double dt_s, std::uint8_t& flags);
  /// An exact zero was sent (a fault, a stale reading, a pause, a stall): the next step()
  /// rises from zero at the rate limit, and the RMS window cools for `dt_s`.
  void zero(double dt_s);
  /// Forget the RMS window and the last force (a new start).
  void reset() { last_ = {}, mean_sq_ = 0; }
  /// The RMS |F| over the window now [N].
  double rms_n() const { return std::sqrt(mean_sq_); }
  const Vec3& last_n() const { return last_; }

 private:
  void heat(double f_sq, double dt_s);
  double continuous_cap(double dt_s) const;
  ForceLimits lim_;
  Vec3 last_;
  double mean_sq_ = 0;  // exponentially windowed mean of |F|^2 [N^2]
};

}  // namespace isotouch::servo
