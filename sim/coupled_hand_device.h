// coupled_hand_device.h - the probe without a haptic device: the operator's hand is a target
// point the UI sets (the mouse: cursor ray through the camera, depth from the wheel), and a
// simulated point-mass device (sim::SimDevice) is coupled to it through the hand's spring and
// damper, so the HIP follows the hand while the servo's force pushes it back out of the
// surface: the proxy stays on the surface and the force a real device would render is the
// one sent to this one.
//
// Threads: set_hand_target() / set_buttons() from one UI thread; read_position_m(),
// write_force_n() and buttons() from the servo thread only (no allocation, lock or
// syscall: the target is three relaxed atomics, a torn read between them is one tick of a
// hand that moved slightly).
#pragma once
#include "isotouch/sim/servo_names.h"

#include <atomic>
#include <cstdint>

#include "isotouch/servo/device_io.h"
#include "isotouch/sim/sim_device.h"
#include "isotouch/core/vec3.h"

namespace isotouch::sim {

class CoupledHandDevice final : public HapticDeviceIO {
 public:
  /// The device starts at rest at `start_m` with the hand there (device = world frame).
  CoupledHandDevice(const SimDeviceParams& params, const Vec3& start_m, double period_s);
  /// Where the operator's hand pulls the device [m]. Non-finite targets are ignored.
  void set_hand_target(const Vec3& target_m);
  Vec3 hand_target() const;
  void set_buttons(std::uint32_t b) { buttons_.store(b, std::memory_order_relaxed); }

  Vec3 read_position_m() override { return dev_.position(); }
  /// Commands the force and advances the device one servo period toward the hand target.
  void write_force_n(const Vec3& force_n) override;
  std::uint32_t buttons() override { return buttons_.load(std::memory_order_relaxed); }

 private:
  SimDevice dev_;
  double period_s_;
  std::atomic<double> tx_, ty_, tz_;
  std::atomic<std::uint32_t> buttons_{0};
};

}  // namespace isotouch::sim
