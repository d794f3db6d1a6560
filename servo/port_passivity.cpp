#include "isotouch/servo/port_passivity.h"

#include <algorithm>
#include <cmath>

#include "isotouch/core/setting_check.h"

namespace isotouch::servo {
namespace {
/// The shortest period the damping's cap alpha_max / dt is taken over [s]: a clock step far
/// below any device loop's would make the cap infinite and the damping NaN.
constexpr double kMinPeriodS = 1e-6;
}  // namespace

PortPassivity::PortPassivity(bool enabled, double alpha_max, double force_limit_n, double hold_period_s)
    : enabled_(enabled), alpha_max_(alpha_max), f_max_(force_limit_n), min_period_s_(kMinPeriodS) {
  core::require_non_negative("PortPassivity", "alpha_max", alpha_max, "N s/m");
  core::require_positive("PortPassivity", "force_limit_n", force_limit_n, "N");
  core::require_non_negative("PortPassivity", "hold_period_s", hold_period_s, "s");
  min_period_s_ = std::max(kMinPeriodS, hold_period_s);
}

Vec3 PortPassivity::tick(double t, const Vec3& x, const Vec3& f_want, const double* e_ref_j, bool control) {
  alpha_ = 0;
  if (!finite(x) || !finite(f_want) || !std::isfinite(t)) {
    // Zero force now; the next sane tick starts the velocity afresh.
    prev_f_ = {};
    started_ = false;
    return {};
  }
  const double dt = t - prev_t_;
  // The work needs no dt: it is counted on every tick after the first, even one whose clock
  // repeated or stepped back. Only the damping, a velocity, needs a period.
  const bool moving = started_ && dt > 0;
  Vec3 dx;  // the motion over the last period, device [m]; the velocity is dx / dt
  if (started_) {
    dx = x - prev_x_;
    const double w = dot(prev_f_, dx);  // work the held force did on the user
    e_out_ += std::max(w, 0.0);  // both, without a branch: w's sign changes from tick to tick
    e_in_ += std::max(-w, 0.0);
    dissipated_ -= dot(prev_damp_, dx);
  }
  Vec3 f = f_want;
  Vec3 damp;
  if (control && moving) {
    // E_out after this tick if the velocity holds (work f.v dt = f.dx): the reference may
    // not be exceeded. alpha = excess / (dt v^2) = excess dt / dx^2, and the damping force
    // -alpha v = -dx excess / dx^2: no division on a tick that needs no damping.
    const double dx2 = dot(dx, dx);
    const double excess = e_out_ + std::max(0.0, dot(f, dx)) - (e_ref_j ? *e_ref_j : e_in_);
    if (excess > 0 && dx2 > 1e-30) {
      const double period = std::max(dt, min_period_s_);
      const bool capped = excess * period > alpha_max_ * dx2;
      const double per_m = capped ? alpha_max_ / period : excess / dx2;  // [N/m] on dx
      alpha_ = per_m * period;
      damp = dx * -per_m;
      f += damp;
      ++active_;
    }
  }
  const double f2 = dot(f, f);
  if (f2 > f_max_ * f_max_) {  // clip, direction kept; the damping's share shrinks with it
    const double scale = f_max_ / std::sqrt(f2);
    f = f * scale;
    damp = damp * scale;
  }
  if (!finite(f)) f = {};  // never hand the device a NaN, whatever the arithmetic met
  prev_t_ = t;
  prev_x_ = x;
  prev_f_ = f;
  prev_damp_ = damp;
  started_ = true;
  return f;
}

void PortPassivity::sent(const Vec3& f_sent) {
  // Squared norms: a root only on a tick whose force a later stage shrank.
  const double want2 = dot(prev_f_, prev_f_), got2 = dot(f_sent, f_sent);
  if (got2 < want2) prev_damp_ = prev_damp_ * std::sqrt(got2 / want2);
  prev_f_ = finite(f_sent) ? f_sent : Vec3{};
}

}  // namespace isotouch::servo
