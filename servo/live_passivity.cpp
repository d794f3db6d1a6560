#include "isotouch/servo/live_passivity.h"

#include <cstdio>

namespace isotouch::servo {

void LivePassivity::start(bool control, double alpha_max_n_s_per_m, double force_limit_n, double hold_s) {
  pc_ = PortPassivity(control, alpha_max_n_s_per_m, force_limit_n, hold_s);
  control_ = control;
  started_ = false;
  device_clock_ = false;
  last_us_ = 0;
  device_us_ = 0;
  first_ns_ = 0;
  banked_ = {};
  control_pub_.store(control, std::memory_order_relaxed);  // set once: not on every tick
  device_clock_pub_.store(false, std::memory_order_relaxed);
  publish();
}

void LivePassivity::restart() {
  banked_.energy_in_j += pc_.energy_in_j();
  banked_.energy_out_j += pc_.energy_out_j();
  banked_.dissipated_j += pc_.dissipated_j();
  banked_.active_ticks += pc_.active_ticks();
  ++banked_.restarts;
  pc_.restart();
  started_ = false;  // the next tick chooses the clock again and has no period
  publish();
}

bool LivePassivity::clock_broke(std::int64_t servo_ns, std::uint32_t device_time_us) const {
  if (device_time_us == 0) return true;  // a reset device, or one without a clock now
  // Modulo 2^32 a wrap is one step, and a step back reads as one of 35 minutes or more: a jump.
  // Integers: no conversion on the tick's path.
  const std::uint32_t step = device_time_us - last_us_;
  return std::int64_t(step) * 1000 > servo_ns - last_ns_ + kClockJumpNs;
}

double LivePassivity::clock_s(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m) {
  // A clock that broke, or one that appeared (the servo's clock stood in for it): afresh.
  if (started_ && (device_clock_ ? clock_broke(servo_ns, device_time_us) : device_time_us != 0)) [[unlikely]]
    restart();
  if (!started_) {
    started_ = true;
    device_clock_ = device_time_us != 0;
    device_clock_pub_.store(device_clock_, std::memory_order_relaxed);  // chosen: published once
    last_us_ = device_time_us;
    device_us_ = 0;
    first_ns_ = last_ns_ = servo_ns;
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
  last_ns_ = servo_ns;
  return double(device_us_) * 1e-6;
}

Vec3 LivePassivity::step(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m, const Vec3& demand_n) {
  const double t = clock_s(servo_ns, device_time_us, x_m);
  last_clock_s_ = t;
  // A non-finite demand goes to the gate as it is: the gate's rule for it is an exact zero
  // at once (a zero from here would be rate-limited down instead). The motion is booked;
  // sent() books that zero.
  if (!finite(demand_n)) [[unlikely]] {
    pc_.observe(t, x_m);
    return demand_n;
  }
  return pc_.step(t, x_m, demand_n);
}

void LivePassivity::skip(std::int64_t servo_ns, std::uint32_t device_time_us, const Vec3& x_m) {
  pc_.observe(clock_s(servo_ns, device_time_us, x_m), x_m);
}

void LivePassivity::sent(const Vec3& f_n) {
  pc_.sent(f_n);
  publish();
}

void LivePassivity::publish() {
  // Relaxed stores: plain moves on x86-64, no fence; a reader gets each figure whole.
  e_in_.store(banked_.energy_in_j + pc_.energy_in_j(), std::memory_order_relaxed);
  e_out_.store(banked_.energy_out_j + pc_.energy_out_j(), std::memory_order_relaxed);
  dissipated_.store(banked_.dissipated_j + pc_.dissipated_j(), std::memory_order_relaxed);
  active_.store(banked_.active_ticks + pc_.active_ticks(), std::memory_order_relaxed);
  restarts_.store(banked_.restarts, std::memory_order_relaxed);
}

std::string describe(const PassivityStats& s) {
  auto mj = [](double j) {
    char b[32];
    std::snprintf(b, sizeof b, "%.3g mJ", j * 1e3);
    return std::string(b);
  };
  return std::string(s.control ? "controller on" : "observer only") + " (" +
         (s.device_clock ? "device clock" : "servo clock") + "): in " + mj(s.energy_in_j) + ", out " +
         mj(s.energy_out_j) + ", dissipated " + mj(s.dissipated_j) + "; damping added on " +
         std::to_string(s.active_ticks) + " ticks, " + std::to_string(s.restarts) + " restarts";
}

PassivityStats LivePassivity::stats() const {
  PassivityStats s;
  s.control = control_pub_.load(std::memory_order_relaxed);
  s.device_clock = device_clock_pub_.load(std::memory_order_relaxed);
  s.energy_in_j = e_in_.load(std::memory_order_relaxed);
  s.energy_out_j = e_out_.load(std::memory_order_relaxed);
  s.dissipated_j = dissipated_.load(std::memory_order_relaxed);
  s.active_ticks = active_.load(std::memory_order_relaxed);
  s.restarts = restarts_.load(std::memory_order_relaxed);
  return s;
}

}  // namespace isotouch::servo
