#include "isotouch/servo/live_passivity.h"

namespace isotouch::servo {

void LivePassivity::start(bool control, double alpha_max_n_s_per_m, double force_limit_n) {
  pc_ = PortPassivity(control, alpha_max_n_s_per_m, force_limit_n);
  control_ = control;
  started_ = false;
  device_clock_ = false;
  last_us_ = 0;
  device_us_ = 0;
  first_ns_ = 0;
  publish();
}

double LivePassivity::clock_s(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m) {
  if (!started_) {
    started_ = true;
    device_clock_ = device_time_us != 0;
    last_us_ = device_time_us;
    first_ns_ = servo_ns;
    servo_t_ = 0;
    last_x_ = x_m;
    return 0;
  }
  if (!device_clock_) {
    // A backend without a clock re-reads its last report until a new one arrives (an SDK's
    // 1 kHz frame under a faster servo, a 100 Hz link): the clock stands still on a repeated
    // position, as the device's clock does on a repeated report, so that the next new one's
    // period spans the ticks it moved in (else its velocity, and the damping, is N-fold).
    if (x_m.x != last_x_.x || x_m.y != last_x_.y || x_m.z != last_x_.z) servo_t_ = double(servo_ns - first_ns_) * 1e-9;
    last_x_ = x_m;
    return servo_t_;
  }
  device_us_ += std::uint32_t(device_time_us - last_us_);  // modulo 2^32: the wrap is one step
  last_us_ = device_time_us;
  return double(device_us_) * 1e-6;
}

Vec3 LivePassivity::step(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m, const Vec3& demand_n) {
  const double t = clock_s(servo_ns, device_time_us, x_m);
  last_clock_s_ = t;
  // A non-finite demand goes to the gate as it is: the gate's rule for it is an exact zero
  // at once (a zero from here would be rate-limited down instead). sent() books that zero.
  if (!finite(demand_n)) return demand_n;
  return pc_.step(t, x_m, demand_n);
}

void LivePassivity::sent(const Vec3& f_n) {
  pc_.sent(f_n);
  publish();
}

void LivePassivity::publish() {
  // Relaxed stores: plain moves on x86-64, no fence; a reader gets each figure whole.
  e_in_.store(pc_.energy_in_j(), std::memory_order_relaxed);
  e_out_.store(pc_.energy_out_j(), std::memory_order_relaxed);
  dissipated_.store(pc_.dissipated_j(), std::memory_order_relaxed);
  active_.store(pc_.active_ticks(), std::memory_order_relaxed);
  control_pub_.store(control_, std::memory_order_relaxed);
  device_clock_pub_.store(device_clock_, std::memory_order_relaxed);
}

PassivityStats LivePassivity::stats() const {
  PassivityStats s;
  s.control = control_pub_.load(std::memory_order_relaxed);
  s.device_clock = device_clock_pub_.load(std::memory_order_relaxed);
  s.energy_in_j = e_in_.load(std::memory_order_relaxed);
  s.energy_out_j = e_out_.load(std::memory_order_relaxed);
  s.dissipated_j = dissipated_.load(std::memory_order_relaxed);
  s.active_ticks = active_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace isotouch::servo
