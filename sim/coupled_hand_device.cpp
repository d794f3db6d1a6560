#include "isotouch/sim/coupled_hand_device.h"

#include <cmath>

namespace isotouch::sim {

CoupledHandDevice::CoupledHandDevice(const SimDeviceParams& params, const Vec3& start_m, double period_s)
    : dev_(params, start_m), period_s_(period_s), tx_(start_m.x), ty_(start_m.y), tz_(start_m.z) {}

void CoupledHandDevice::set_hand_target(const Vec3& t) {
  if (!std::isfinite(t.x) || !std::isfinite(t.y) || !std::isfinite(t.z)) return;
  tx_.store(t.x, std::memory_order_relaxed);
  ty_.store(t.y, std::memory_order_relaxed);
  tz_.store(t.z, std::memory_order_relaxed);
}

Vec3 CoupledHandDevice::hand_target() const {
  return {tx_.load(std::memory_order_relaxed), ty_.load(std::memory_order_relaxed), tz_.load(std::memory_order_relaxed)};
}

void CoupledHandDevice::write_force_n(const Vec3& f) {
  dev_.command_force(f);
  dev_.step(period_s_, hand_target(), Vec3{0, 0, 0});  // the hand holds still within a tick
}

}  // namespace isotouch::sim
