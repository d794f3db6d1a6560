// device_io.h - the device side of the servo loop (HAPI: updateDeviceValues / sendOutput):
// the device model (capabilities, status, one reading per tick) and its interface.
#pragma once
#include "isotouch/servo/core_names.h"
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "isotouch/core/vec3.h"
#include "isotouch/servo/input_phase.h"

namespace isotouch::servo {

/// What a device can do. Device frame, SI units. Defaults: a device without limits (the
/// simulated one): an infinite workspace, force and gains.
struct DeviceCaps {
  std::string name = "device";  ///< for messages ("Polhem v1", "isotouch-devemu", ...)
  int dof = 3;                  ///< translational degrees of freedom with force
  Vec3 workspace_min_m{-INFINITY, -INFINITY, -INFINITY};  ///< workspace box, device [m]
  Vec3 workspace_max_m{INFINITY, INFINITY, INFINITY};
  double max_force_n = INFINITY;              ///< largest |F| the device renders [N] (its peak)
  /// Largest |F| the device sustains [N] (OpenHaptics' HD_NOMINAL_MAX_CONTINUOUS_FORCE): the
  /// servo's gate keeps the RMS |F| over continuous_window_s at or below it (force_gate.h).
  double max_continuous_force_n = INFINITY;
  double continuous_window_s = 0;             ///< that RMS's window [s] (0: the gate's default, 10 s)
  /// Largest rate of change of the force the device should be sent [N/s] (0: the gate's
  /// default, max_force_n over 2 ms when the peak is finite).
  double max_force_rate_n_per_s = 0;
  /// The device applies each force in its own loop at this rate [Hz] (OpenHaptics' servo loop,
  /// Force Dimension's thread, a v1 device's firmware at its report rate): a faster servo is
  /// refused, as its ticks between two of the device's would be lost (and read stale). 0: the
  /// device applies what it is sent as it comes (the lock-step Polhem, links, simulation).
  double output_rate_hz = 0;
  double max_stiffness_n_per_m = INFINITY;    ///< largest stable stiffness [N/m]
  double max_damping_n_s_per_m = INFINITY;    ///< largest stable damping [N s/m]
  double native_rate_hz = 0;                  ///< the device's own report rate [Hz] (0: the servo's)
  int buttons = 0;                            ///< number of buttons
  double position_resolution_m = 0;           ///< smallest position step [m] (0: continuous)
  double watchdog_s = 0;                      ///< the device zeroes its force after this long without output [s] (0: none)
  /// A reading older than this at a tick is stale: zero force that tick [s]. 0: the servo's
  /// default, two of its periods. A device whose readings come slower than the servo ticks
  /// (over a network, or in lock-step with a remote loop) sets a few of its own periods, else
  /// every tick between two readings would be stale (docs/devices.md). The servo's own
  /// ServoThreadConfig::stale_timeout_s, when set, overrides it.
  double stale_timeout_s = 0;

  /// True if `p` [m, device] is finite and inside the workspace box.
  bool contains(const Vec3& p) const {
    return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && p.x >= workspace_min_m.x &&
           p.y >= workspace_min_m.y && p.z >= workspace_min_m.z && p.x <= workspace_max_m.x &&
           p.y <= workspace_max_m.y && p.z <= workspace_max_m.z;
  }
};

/// The device's state as the servo sees it at a tick.
enum class DeviceStatus : std::uint8_t {
  kOk,            ///< a report arrived and the device reports no fault
  kStale,         ///< no fresh report within the backend's own timeout
  kDisconnected,  ///< the link is down (unplugged, emulator gone); the backend reconnects
  kFault,         ///< the device reports a fault (or sent a report that is refused)
  /// The device is there but not calibrated yet (a Polhem since it was opened, an OpenHaptics
  /// device whose hdCheckCalibration is not ok): its pose is not where it reads, so the servo
  /// sends zero force and does not tick the renderer, as for a fault, and once calibrated
  /// resets the renderer and ramps the force in. Not a fault: a user who calibrates after
  /// the start is expected (counted as DeviceCounters::uncalibrated, not as fault; the front
  /// ends say "waiting for calibration" and do not exit with kDeviceLost for it). Last, so
  /// the values before it keep their numbers.
  kUncalibrated,
};

inline const char* to_string(DeviceStatus s) {
  switch (s) {
    case DeviceStatus::kOk: return "ok";
    case DeviceStatus::kStale: return "stale";
    case DeviceStatus::kDisconnected: return "disconnected";
    case DeviceStatus::kFault: return "fault";
    case DeviceStatus::kUncalibrated: return "waiting for calibration";
  }
  return "?";
}

/// One reading of the device: the newest report and when it arrived.
struct DeviceReading {
  Vec3 position_m;              ///< end effector, device [m]
  std::uint32_t buttons = 0;    ///< bit i: button i down
  DeviceStatus status = DeviceStatus::kOk;
  /// CLOCK_MONOTONIC when the host received the report [ns]; 0: synchronous (the reading
  /// is made by the call itself, always fresh: the simulated, null and playback devices).
  std::int64_t received_ns = 0;
  std::uint64_t sequence = 0;       ///< the report's sequence number (0: the protocol has none)
  std::uint32_t device_time_us = 0; ///< the device's clock when it sent the report [us] (wraps)
  /// Incremented when the link came back after a disconnect (the servo ramps the force in).
  std::uint32_t connection = 0;
  /// The device says its force output is off (v1: force-enabled flag clear): what the host
  /// sends now is not rendered and would step in when it is back on (the servo holds its
  /// ramp at 0 meanwhile).
  bool force_off = false;
  /// The device's watchdog zeroed its force (no output report within DeviceCaps::watchdog_s).
  bool watchdog_tripped = false;
};

/// A haptic device as the servo thread sees it. read(), read_position_m(), buttons() and
/// write_force_n() happen on the servo thread once per tick and must not allocate, lock,
/// block or make a syscall (backends with I/O do it on their own threads).
class HapticDeviceIO {
 public:
  virtual ~HapticDeviceIO() = default;
  /// End-effector position, device [m].
  virtual Vec3 read_position_m() = 0;
  /// Force to render until the next call [N], device axes. Must accept any finite value
  /// (the device clips at its own limit) and refuse non-finite ones.
  virtual void write_force_n(const Vec3& force_n) = 0;
  /// The buttons as of the last read_position_m() (bit i: button i down); 0 without buttons.
  virtual std::uint32_t buttons() { return 0; }
  /// The newest reading. Default: a synchronous device (read_position_m(), then buttons()).
  virtual DeviceReading read() {
    DeviceReading r;
    r.position_m = read_position_m();
    r.buttons = buttons();
    return r;
  }
  /// What the device can do (any thread; fixed once the device is open).
  virtual DeviceCaps caps() const { return {}; }
  /// Force output on or off (off: the device is sent zero force with its enable flag
  /// cleared). While on, a device with its own output thread takes the force off by itself
  /// (zero, enable cleared) once write_force_n() has not been called for `stall_s` [s]: the
  /// caller that writes says how long a silence means it stalled (ServoThread: 2.5 of its
  /// periods); <= 0 or not finite: the device's default. Returns the device's count of
  /// such stalls, which the caller reads every tick: a change means the force is off and
  /// must ramp in from 0 (the device also sends the first write after a stall as zero);
  /// null for a device written to directly, which keeps the last force. Any thread.
  virtual const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) {
    (void)on, (void)stall_s;
    return nullptr;
  }
  /// The sequence number of the report the next write_force_n() answers (echoed in the
  /// output report, so the device can measure report-to-force latency). Servo thread.
  virtual void answer(std::uint64_t sequence) { (void)sequence; }
  /// A link that sends an input and waits for the force answering it: when its next input
  /// is due and its period (input_phase.h); unknown by default. Servo thread: lock-free.
  virtual InputPhase input_phase() const { return {}; }
};

}  // namespace isotouch::servo
