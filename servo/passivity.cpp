#include "isotouch/servo/passivity.h"

#include <algorithm>
#include <cmath>

namespace isotouch::servo {

Vec3 PassivityController::step(const Vec3& x, const Vec3& f_env) {
  alpha_ = 0;
  if (!finite(x) || !finite(f_env)) {
    // Zero force is sent this tick: the force held over the next period is zero, and the
    // position of this tick is unknown, so the next sane tick starts the velocity afresh
    // (it must not charge prev_f_ over a displacement it never acted on).
    prev_f_ = {};
    started_ = false;
    return {};
  }
  Vec3 v;
  if (started_) {
    // Work done on the environment over the last period by the force that was held.
    energy_ -= dot(prev_f_, x - prev_x_);
    v = (x - prev_x_) / T_;
  }
  Vec3 f = f_env;
  if (enabled_ && started_) {
    const double v2 = dot(v, v);
    const double predicted = energy_ - dot(f, v) * T_;  // if the velocity holds
    if (predicted < 0 && v2 > 1e-18) {
      alpha_ = std::min(alpha_max_, -predicted / (T_ * v2));
      f = f - v * alpha_;
    }
  }
  saturate(f, f_max_);
  prev_x_ = x;
  prev_f_ = f;
  started_ = true;
  return f;
}

}  // namespace isotouch::servo
