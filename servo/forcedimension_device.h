// forcedimension_device.h - Force Dimension omega, sigma, delta, lambda and the Novint Falcon
// through the Force Dimension SDK (libdhd.so, loaded with dlopen: no SDK at build time).
// The dhd calls are USB transfers: they run on a device thread of this class, never in the
// servo tick, which only touches two latest-value cells.
//
// Frames. Force Dimension: x toward the user, y right, z up, m. isotouch's device frame for
// desk devices: x right, y away from the user, z up. So device = (y, -x, z) and
// force_FD = (-Fy, Fx, Fz) (a rotation about z).
#pragma once
#include "isotouch/servo/core_names.h"
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/servo/dhd_api.h"
#include "isotouch/servo/sdk_device.h"

namespace isotouch::servo {

/// libdhd.so's functions isotouch calls (null until loaded; dhdErrorGetLastStr optional).
struct DhdApi {
  DhdGetDeviceCount dhdGetDeviceCount = nullptr;
  DhdOpenID dhdOpenID = nullptr;
  DhdClose dhdClose = nullptr;
  DhdGetSystemType dhdGetSystemType = nullptr;
  DhdGetPosition dhdGetPosition = nullptr;
  DhdGetButtonMask dhdGetButtonMask = nullptr;
  DhdSetForce dhdSetForce = nullptr;
  DhdEnableForce dhdEnableForce = nullptr;
  DhdErrorGetLastStr dhdErrorGetLastStr = nullptr;
  DhdEnableExpertMode dhdEnableExpertMode = nullptr;  // optional (expert SDK)
  DhdSetWatchdog dhdSetWatchdog = nullptr;            // optional (SDK 3.3.2 and later)
  DhdGetStatus dhdGetStatus = nullptr;                // optional: without it a firmware force-off is not seen
  SdkLibrary lib;
};

/// Loads libdhd.so: $ISOTOUCH_DHD_LIBRARY if set, else libdhd.so, libdhd.so.3. "" or what is
/// missing; `api.lib.searched` says what was tried.
std::string load_dhd_api(DhdApi& api);

/// A Force Dimension system type -> its model name and limits (CHAI3D's table; unknown
/// types: CHAI3D's default, an omega.3's).
DeviceCaps dhd_system_caps(int system_type);

/// `isotouch devices`: one line per device the SDK counts (index, model, system type).
std::vector<std::string> list_forcedimension(const DhdApi& api);

/// FD position [m, FD frame] -> isotouch device frame [m].
inline Vec3 dhd_to_device_m(double x, double y, double z) { return {y, -x, z}; }
/// isotouch device-frame force [N] -> FD frame [N].
inline Vec3 device_to_dhd_force(const Vec3& f) { return {-f.y, f.x, f.z}; }

/// One Force Dimension device, by index (0 = the first).
class ForceDimensionDevice final : public SdkDevice {
 public:
  explicit ForceDimensionDevice(int index = 0, double rate_hz = 2000);
  ~ForceDimensionDevice() override;  ///< close()
  /// Opens the device, reads its type and limits, starts the device thread and waits for its
  /// first reading. @throws std::runtime_error naming the library searched or the SDK's error.
  void open();
  /// The device thread's last act: an exact zero force, force disabled, the device closed.
  void close() override;
  /// The firmware watchdog set at open() [s] (0: the SDK has no dhdSetWatchdog): the device
  /// disables its forces by itself when no force command comes for this long (isotouch
  /// killed, hung, or its device thread starved).
  double watchdog_s() const { return caps_.watchdog_s; }
  /// "" or why the device thread did not get SCHED_FIFO (valid after open()).
  std::string realtime_note() const;
  /// Times the device was opened again after it was gone (unplugged, powered off).
  long reopens() const { return reopens_.load(); }
  std::string description() const { return description_; }
  std::string last_error() const;     ///< the last failed call and the SDK's reason ("" none)
  long errors() const { return errors_.load(); }
  long periods() const { return periods_.load(); }
  /// Times the firmware turned the forces off by itself while isotouch had them on, read from
  /// dhdGetStatus: its watchdog (the device thread starved past watchdog_s()), and any cause.
  long watchdog_trips() const { return watchdog_trips_.load(); }
  long firmware_force_offs() const { return force_offs_.load(); }
  std::string sdk_status() const override;

 private:
  void loop();
  void period(std::int64_t now, bool& force_on);
  void note_error(const char* call);
  void set_watchdog(bool record);
  void reopen(std::int64_t now, bool& force_on);
  void read_status(bool& force_on);

  int index_;
  double rate_hz_;
  DhdApi api_;
  char id_ = 0;
  std::string description_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<long> errors_{0}, periods_{0}, reopens_{0}, watchdog_trips_{0}, force_offs_{0};
  mutable std::mutex note_mu_;
  std::string last_error_;  // note_mu_
  std::string realtime_note_;  // note_mu_
  Vec3 last_position_;  // device thread
  bool down_ = false;   // device thread: the last read failed
  std::int64_t last_reopen_ns_ = 0;  // device thread: the last attempt to open the device again
  // Device thread: the firmware turned the forces off by itself (dhdGetStatus). Held off, with
  // zero force and readings that say force_off (watchdog_tripped for its watchdog), until the
  // firmware's force is on again (after a watchdog trip: turned on again by this thread; any
  // other cause, a button or a velocity or deadman switch: by the user at the device) and the
  // servo's latest force is an exact zero made after it read such a reading (it holds its
  // ramp at 0 while force_off is set): the force then ramps in from 0, never steps back.
  bool fw_off_ = false;
  bool fw_on_ = false;                // the firmware's force state at the last dhdGetStatus
  int status_every_ = 1;              // dhdGetStatus every this many periods (about 1 kHz)
  int fw_off_cause_ = 0;
  std::uint64_t fw_off_reading_ = 0;  // the sequence of the first reading that said so
};

}  // namespace isotouch::servo
