// openhaptics_device.h - 3D Systems Touch, Touch X, Phantom Premium through the OpenHaptics
// HD API (libHD.so, loaded with dlopen: no SDK at build time). The HD scheduler's callback
// (its thread, the device's rate, 1 kHz) publishes each pose and applies the servo's latest
// force with the stall rule; isotouch's servo thread stays the one that renders.
//
// Frames. HD: x right, y up, z toward the user, mm. isotouch's device frame for desk devices:
// x right, y away from the user, z up, m. So device = (x, -z, y) / 1000 and
// force_HD = (Fx, Fz, -Fy) (a rotation, right-handed both sides).
#pragma once
#include "isotouch/servo/core_names.h"
#include <string>

#include "isotouch/servo/hd_api.h"
#include "isotouch/servo/sdk_device.h"

namespace isotouch::servo {

/// libHD.so's functions isotouch calls (null until loaded).
struct HdApi {
  HHD (*hdInitDevice)(HDstring) = nullptr;
  void (*hdDisableDevice)(HHD) = nullptr;
  void (*hdMakeCurrentDevice)(HHD) = nullptr;
  void (*hdBeginFrame)(HHD) = nullptr;
  void (*hdEndFrame)(HHD) = nullptr;
  HDErrorInfo (*hdGetError)() = nullptr;
  void (*hdGetDoublev)(HDenum, HDdouble*) = nullptr;
  void (*hdGetIntegerv)(HDenum, HDint*) = nullptr;
  HDstring (*hdGetString)(HDenum) = nullptr;
  void (*hdSetDoublev)(HDenum, const HDdouble*) = nullptr;
  void (*hdEnable)(HDenum) = nullptr;
  void (*hdDisable)(HDenum) = nullptr;
  void (*hdStartScheduler)() = nullptr;
  void (*hdStopScheduler)() = nullptr;
  HDSchedulerHandle (*hdScheduleAsynchronous)(HDSchedulerCallback, void*, HDushort) = nullptr;
  void (*hdUnschedule)(HDSchedulerHandle) = nullptr;
  HDenum (*hdCheckCalibration)() = nullptr;
  void (*hdUpdateCalibration)(HDenum) = nullptr;
  SdkLibrary lib;
};

/// Loads libHD.so: $ISOTOUCH_HD_LIBRARY if set, else libHD.so, libHD.so.3.4, libHD.so.3.
/// `api.lib` says what was searched; "" or what is missing (no library, absent functions).
std::string load_hd_api(HdApi& api);

/// `isotouch devices`: the default device's model, serial and calibration, or why none
/// (hdInitDevice's error); the device is released again.
std::string list_openhaptics(const HdApi& api);

/// HD position [mm, HD frame] -> isotouch device frame [m].
inline Vec3 hd_to_device_m(const double mm[3]) { return Vec3{mm[0], -mm[2], mm[1]} * 1e-3; }
/// isotouch device-frame force [N] -> HD frame [N].
inline void device_to_hd_force(const Vec3& f, double out[3]) { out[0] = f.x, out[1] = f.z, out[2] = -f.y; }

/// One OpenHaptics device. open() initialises it (the default device or the named one),
/// reads its capabilities, enables force output and starts the scheduler with the callback.
class OpenHapticsDevice final : public SdkDevice {
 public:
  /// `name`: the device's configuration name ("Default Device", "PHANToM 1"); "" = default.
  explicit OpenHapticsDevice(std::string name = "");
  ~OpenHapticsDevice() override;  ///< close()
  /// @throws std::runtime_error naming the library searched or the HD error (hdGetError).
  void open();
  /// Applies an exact zero force, stops the scheduler, disables the device. Idempotent.
  void close() override;
  /// "openhaptics:NAME (MODEL, serial S, calibration ok)" for the log.
  std::string description() const { return description_; }
  /// "" or a note about the calibration (needs update / manual input).
  std::string warning() const { return warning_; }
  /// The last HD error the callback saw ("" none), e.g. "HD_COMM_ERROR (0x302)".
  std::string last_error() const;
  long errors() const { return errors_.load(); }   ///< HD errors seen by the callback
  long frames() const { return frames_.load(); }   ///< callback runs
  std::string sdk_status() const override;
  /// hdCheckCalibration said ok (at open, or after the scheduler updated it). Until then
  /// every reading is a fault and the device gets zero force.
  bool calibrated() const { return calibrated_.load(); }
  /// hdUpdateCalibration calls made by the scheduler callback.
  long calibration_updates() const { return calibration_updates_.load(); }

 private:
  static HDCallbackCode callback(void* self);
  HDCallbackCode tick();
  std::string hd_error(const char* call) const;
  void read_caps();
  void choose_calibration_style();
  bool calibrate_in_frame();

  std::string name_, description_, warning_;
  HdApi api_;
  HHD hhd_ = hd::kInvalidHandle;
  HDSchedulerHandle sched_ = 0;
  bool running_ = false;
  std::atomic<bool> closing_{false};
  std::atomic<long> frames_{0}, errors_{0}, zero_frames_{0};
  std::atomic<HDerror> last_error_{hd::kSuccess};
  bool enabled_output_ = false;  // HD_FORCE_OUTPUT as last set
  bool down_ = false;            // callback thread: the last frame reported a device error
  HDenum cal_style_ = 0;         // the style hdUpdateCalibration is given (0: none usable)
  std::atomic<bool> calibrated_{false};
  std::atomic<long> calibration_updates_{0};
};

}  // namespace isotouch::servo
