#include "isotouch/servo/port_passivity.h"

#include <algorithm>

namespace isotouch::servo {

Vec3 PortPassivity::tick(double t, const Vec3& x, const Vec3& f_want, const double* e_ref_j) {
  alpha_ = 0;
  if (!finite(x) || !finite(f_want) || !(t == t)) {
    // Zero force now; the next sane tick starts the velocity afresh.
    prev_f_ = {};
    started_ = false;
    return {};
  }
  const double dt = t - prev_t_;
  Vec3 v;
  if (started_ && dt > 0) {
    const Vec3 dx = x - prev_x_;
    const double w = dot(prev_f_, dx);  // work the held force did on the user
    (w > 0 ? e_out_ : e_in_) += std::abs(w);
    dissipated_ -= dot(prev_damp_, dx);
    v = dx / dt;
  }
  Vec3 f = f_want;
  Vec3 damp;
  if (enabled_ && started_ && dt > 0) {
    const double v2 = dot(v, v);
    // E_out after this tick if the velocity holds: the reference may not be exceeded.
    const double excess = e_out_ + std::max(0.0, dot(f, v) * dt) - (e_ref_j ? *e_ref_j : e_in_);
    if (excess > 0 && v2 > 1e-18) {
      alpha_ = std::min(alpha_max_, excess / (dt * v2));
      damp = v * -alpha_;
      f += damp;
      ++active_;
    }
  }
  saturate(f, f_max_);
  prev_t_ = t;
  prev_x_ = x;
  prev_f_ = f;
  prev_damp_ = damp;
  started_ = true;
  return f;
}

}  // namespace isotouch::servo
