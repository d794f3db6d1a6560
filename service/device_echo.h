// device_echo.h - what `isotouch serve` sends its clients about the device: the servo's newest
// force and the volume's frame (RasEcho), kept for the TRANSFORM stream's device and for a
// `--haptic` device (EchoDevice, every call forwarded to the factory's device).
// Frames: the servo works in the grid frame [m] (engine/volume.h); clients get RAS [mm] for
// points and RAS [N] for the force (grid axes -> LPS by the volume's direction -> RAS).
// Part of isotouch::igtl_device.
#pragma once
#include <chrono>
#include <cstdint>

#include "isotouch/engine/volume.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/latest_value.h"

namespace isotouch::service {

/// The servo's newest force and the volume's frame, for the HIP, proxy and force TRANSFORMs.
class RasEcho {
 public:
  /// The volume whose frames the points and forces are in. Only while no servo runs.
  void set_frame(const engine::Volume& v);
  const engine::Volume& frame() const { return frame_; }
  /// The servo wrote `f` [N, grid axes] now. Servo thread: no allocation, lock or syscall
  /// (the clock is the vDSO's).
  void store(const core::Vec3& f) { force_.store({f, now_ns()}); }
  /// When the servo last wrote a force [ns, steady] (0: never).
  std::int64_t written_ns() const { return force_.load().written_ns; }
  /// The force to send now [N, RAS]: the servo's newest, or zero when the servo has not
  /// written one for `stall_s` (stopped or stalled: no force left on). Any thread.
  core::Vec3 force_ras_n(double stall_s) const;
  /// A force in grid axes [N] -> RAS [N].
  core::Vec3 to_ras_n(const core::Vec3& f) const;
  /// Grid frame point [m] -> RAS [mm] (for the HIP and proxy sent out).
  core::Vec3 grid_to_ras_mm(const core::Vec3& g) const;

  static std::int64_t now_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
  }

 private:
  struct Force {
    core::Vec3 f;
    std::int64_t written_ns = 0;
  };
  servo::LatestValue<Force> force_;
  engine::Volume frame_;  // grid, direction (voxels left empty)
};

/// A device opened by the `--haptic` factory as serve's device: every call forwarded to it,
/// the force the servo writes (after its safety gate: ramp-in, clamp, zero when stale) kept
/// in echo() for the clients.
class EchoDevice final : public servo::HapticDeviceIO {
 public:
  explicit EchoDevice(servo::HapticDeviceIO& d) : d_(d) {}
  RasEcho& echo() { return echo_; }

  core::Vec3 read_position_m() override { return d_.read_position_m(); }
  void write_force_n(const core::Vec3& f) override {
    echo_.store(f);
    d_.write_force_n(f);
  }
  std::uint32_t buttons() override { return d_.buttons(); }
  servo::DeviceReading read() override { return d_.read(); }
  servo::DeviceCaps caps() const override { return d_.caps(); }
  const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) override { return d_.enable_force(on, stall_s); }
  void answer(std::uint64_t sequence) override { d_.answer(sequence); }

 private:
  servo::HapticDeviceIO& d_;
  RasEcho echo_;
};

}  // namespace isotouch::service
