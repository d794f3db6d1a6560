#include "isotouch/servo/force_gate.h"

#include <algorithm>

#include "isotouch/servo/device_io.h"

namespace isotouch::servo {
namespace {
bool all_finite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
// A limit that is not a positive number is no limit.
double limit_or_inf(double v) { return v > 0 ? v : INFINITY; }
}  // namespace

ForceLimits force_limits(const DeviceCaps& caps, double scene_limit_n, double rate_n_per_s) {
  ForceLimits l;
  l.peak_n = std::min(limit_or_inf(scene_limit_n), limit_or_inf(caps.max_force_n));
  l.continuous_n = limit_or_inf(caps.max_continuous_force_n);
  if (caps.continuous_window_s > 0) l.continuous_window_s = caps.continuous_window_s;
  if (rate_n_per_s > 0 && std::isfinite(rate_n_per_s)) l.rate_n_per_s = rate_n_per_s;
  else if (caps.max_force_rate_n_per_s > 0) l.rate_n_per_s = caps.max_force_rate_n_per_s;
  else if (std::isfinite(l.peak_n)) l.rate_n_per_s = l.peak_n / kDefaultPeakRiseS;
  return l;
}

void ForceGate::heat(double f_sq, double dt_s) {
  if (!(lim_.continuous_window_s > 0) || !(dt_s > 0)) return;
  const double a = 1.0 - std::exp(-dt_s / lim_.continuous_window_s);
  mean_sq_ += (f_sq - mean_sq_) * a;
}

void ForceGate::zero(double dt_s) {
  last_ = {};
  heat(0, std::isfinite(dt_s) ? dt_s : 0);
}

double ForceGate::continuous_cap(double dt_s) const {
  const double c = lim_.continuous_n;
  if (!(lim_.continuous_window_s > 0) || !std::isfinite(c)) return INFINITY;
  const double c_sq = c * c;
  if (mean_sq_ >= c_sq) return c;  // at the limit (or just past it after a rate-limited descent): hold it
  const double a = 1.0 - std::exp(-dt_s / lim_.continuous_window_s);
  if (!(a > 0)) return INFINITY;  // no time passes: no heat
  // The largest |F| whose tick leaves the windowed mean of |F|^2 at c^2: m + (f^2 - m) a = c^2.
  return std::sqrt((c_sq - mean_sq_ * (1 - a)) / a);
}

Vec3 ForceGate::step(const Vec3& demand, double dt_s, std::uint8_t& flags) {
  flags = 0;
  if (!(dt_s > 0) || !std::isfinite(dt_s)) dt_s = 0;
  // A non-finite demand (a renderer's fault) makes every step below non-finite (NaN compares
  // false: nothing clamps it), so the last line turns it into an exact zero at once, not a
  // ramp down.
  Vec3 f = demand;
  double m = norm(f);
  if (m > lim_.peak_n) f = f * (lim_.peak_n / m), m = lim_.peak_n, flags |= kGatePeak;
  if (const double cap = continuous_cap(dt_s); m > cap) f = f * (cap / m), flags |= kGateContinuous;
  const Vec3 change = f - last_;
  const double c = norm(change), allowed = lim_.rate_n_per_s * std::min(dt_s, lim_.rate_dt_cap_s);
  if (c > allowed) f = last_ + change * (allowed / c), flags |= kGateRate;
  if (!all_finite(f)) f = {}, flags |= kGateNonFinite;
  last_ = f;
  heat(dot(f, f), dt_s);
  return f;
}

}  // namespace isotouch::servo
