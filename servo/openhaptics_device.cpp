#include "isotouch/servo/openhaptics_device.h"

#include <time.h>

#include <cstdio>
#include <stdexcept>

namespace isotouch::servo {
namespace hd {
const char* error_name(HDerror code) {
  switch (code) {
    case kSuccess: return "HD_SUCCESS";
    case kInvalidEnum: return "HD_INVALID_ENUM";
    case kInvalidValue: return "HD_INVALID_VALUE";
    case kInvalidOperation: return "HD_INVALID_OPERATION";
    case kInvalidInputType: return "HD_INVALID_INPUT_TYPE";
    case kBadHandle: return "HD_BAD_HANDLE";
    case kWarmMotors: return "HD_WARM_MOTORS";
    case kExceededMaxForce: return "HD_EXCEEDED_MAX_FORCE";
    case kExceededMaxForceImpulse: return "HD_EXCEEDED_MAX_FORCE_IMPULSE";
    case kExceededMaxVelocity: return "HD_EXCEEDED_MAX_VELOCITY";
    case kForceError: return "HD_FORCE_ERROR";
    case kDeviceFault: return "HD_DEVICE_FAULT";
    case kDeviceAlreadyInitiated: return "HD_DEVICE_ALREADY_INITIATED";
    case kCommError: return "HD_COMM_ERROR";
    case kCommConfigError: return "HD_COMM_CONFIG_ERROR";
    case kTimerError: return "HD_TIMER_ERROR";
    case kIllegalBegin: return "HD_ILLEGAL_BEGIN";
    case kIllegalEnd: return "HD_ILLEGAL_END";
    case kFrameError: return "HD_FRAME_ERROR";
    case kInvalidPriority: return "HD_INVALID_PRIORITY";
    case kSchedulerFull: return "HD_SCHEDULER_FULL";
    case kInvalidLicense: return "HD_INVALID_LICENSE";
  }
  return "an unknown HD error";
}
}  // namespace hd

namespace {
std::string error_text(HDerror code, int internal) {
  char b[96];
  std::snprintf(b, sizeof b, "%s (0x%03x, internal %d)", hd::error_name(code), code, internal);
  return b;
}
void sleep_ms(int ms) {
  const timespec ts{0, long(ms) * 1000000L};
  nanosleep(&ts, nullptr);
}
}  // namespace

std::string load_hd_api(HdApi& a) {
  a.lib = load_sdk("ISOTOUCH_HD_LIBRARY", {"libHD.so", "libHD.so.3.4", "libHD.so.3"});
  if (!a.lib) return "OpenHaptics HD library not found (searched: " + a.lib.searched + ")";
  std::string missing;
  sdk_symbol(a.lib, "hdInitDevice", a.hdInitDevice, missing);
  sdk_symbol(a.lib, "hdDisableDevice", a.hdDisableDevice, missing);
  sdk_symbol(a.lib, "hdMakeCurrentDevice", a.hdMakeCurrentDevice, missing);
  sdk_symbol(a.lib, "hdBeginFrame", a.hdBeginFrame, missing);
  sdk_symbol(a.lib, "hdEndFrame", a.hdEndFrame, missing);
  sdk_symbol(a.lib, "hdGetError", a.hdGetError, missing);
  sdk_symbol(a.lib, "hdGetDoublev", a.hdGetDoublev, missing);
  sdk_symbol(a.lib, "hdGetIntegerv", a.hdGetIntegerv, missing);
  sdk_symbol(a.lib, "hdGetString", a.hdGetString, missing);
  sdk_symbol(a.lib, "hdSetDoublev", a.hdSetDoublev, missing);
  sdk_symbol(a.lib, "hdEnable", a.hdEnable, missing);
  sdk_symbol(a.lib, "hdDisable", a.hdDisable, missing);
  sdk_symbol(a.lib, "hdStartScheduler", a.hdStartScheduler, missing);
  sdk_symbol(a.lib, "hdStopScheduler", a.hdStopScheduler, missing);
  sdk_symbol(a.lib, "hdScheduleAsynchronous", a.hdScheduleAsynchronous, missing);
  sdk_symbol(a.lib, "hdUnschedule", a.hdUnschedule, missing);
  sdk_symbol(a.lib, "hdCheckCalibration", a.hdCheckCalibration, missing);
  sdk_symbol(a.lib, "hdUpdateCalibration", a.hdUpdateCalibration, missing);
  if (!missing.empty()) return a.lib.path + " lacks " + missing + " (not the OpenHaptics HD library?)";
  return {};
}

OpenHapticsDevice::OpenHapticsDevice(std::string name) : name_(std::move(name)) {
  default_stall_s_ = 0.0025;
}

OpenHapticsDevice::~OpenHapticsDevice() { close(); }

std::string OpenHapticsDevice::hd_error(const char* call) const {
  const HDErrorInfo e = api_.hdGetError();
  if (e.errorCode == hd::kSuccess) return {};
  return std::string(call) + ": " + error_text(e.errorCode, e.internalErrorCode);
}

void OpenHapticsDevice::read_caps() {
  const HdApi& a = api_;
  DeviceCaps c;
  double v = 0, ws[6] = {};
  int n = 0;
  const char* model = a.hdGetString(hd::kDeviceModelType);
  c.name = std::string("OpenHaptics ") + (model ? model : "device");
  a.hdGetDoublev(hd::kNominalMaxForce, &v), c.max_force_n = v;
  // What the motors sustain without heating (the SDK's PreventWarmMotors example clamps to
  // it): the servo's gate holds the RMS |F| over its window there. 0 or an error: none said.
  v = 0;
  a.hdGetDoublev(hd::kNominalMaxContinuousForce, &v);
  if (hd_error("hdGetDoublev(HD_NOMINAL_MAX_CONTINUOUS_FORCE)").empty() && v > 0 && v <= c.max_force_n)
    c.max_continuous_force_n = v;
  a.hdGetDoublev(hd::kNominalMaxStiffness, &v), c.max_stiffness_n_per_m = v * 1e3;  // N/mm -> N/m
  a.hdGetDoublev(hd::kNominalMaxDamping, &v), c.max_damping_n_s_per_m = v * 1e3;   // N s/mm -> N s/m
  a.hdGetDoublev(hd::kUsableWorkspaceDimensions, ws);  // min x, y, z, max x, y, z [mm]
  // The box in isotouch's frame: y = -z_HD, so its bounds swap.
  c.workspace_min_m = Vec3{ws[0], -ws[5], ws[1]} * 1e-3;
  c.workspace_max_m = Vec3{ws[3], -ws[2], ws[4]} * 1e-3;
  a.hdGetIntegerv(hd::kOutputDof, &n), c.dof = n;
  a.hdGetIntegerv(hd::kUpdateRate, &n), c.native_rate_hz = n;
  // The HD scheduler applies each force once a frame: a servo faster than it is refused, and
  // the stall rule acts in its periods (SdkDevice::enable_force).
  c.output_rate_hz = n > 0 ? n : 1000;
  device_period_s_ = 1.0 / c.output_rate_hz;
  c.buttons = 2;  // Touch, Phantom: two stylus buttons (HD_DEVICE_BUTTON_1, _2)
  caps_ = c;
  const char* serial = a.hdGetString(hd::kDeviceSerialNumber);
  const HDenum cal = a.hdCheckCalibration();
  const char* cal_text = cal == hd::kCalibrationOk ? "ok"
                         : cal == hd::kCalibrationNeedsUpdate ? "needs update"
                         : cal == hd::kCalibrationNeedsManualInput ? "needs manual input (put the stylus in its inkwell)"
                                                                   : "unknown";
  choose_calibration_style();
  calibrated_ = cal == hd::kCalibrationOk;
  if (!calibrated_)
    warning_ = "openhaptics: calibration " + std::string(cal_text) +
               (cal_style_ == 0 ? ": the device offers no automatic or inkwell calibration; no force until it is done "
                                  "(Touch Setup / the device's own calibration)"
                                : ": updated from the HD scheduler as the SDK's Calibration example does; no force until "
                                  "hdCheckCalibration says ok");
  description_ = "openhaptics:" + (name_.empty() ? std::string("default") : name_) + " (" + c.name + ", serial " +
                 (serial ? serial : "?") + ", calibration " + cal_text + ", " + api_.lib.path + ")";
}

/// The style the SDK's Calibration example prefers among those the device offers: automatic,
/// then the inkwell (both updated from a scheduler callback). Encoder reset needs the device
/// held at its reset position before the scheduler starts (a prompt isotouch cannot make):
/// not chosen, the force stays off until the device is calibrated otherwise.
void OpenHapticsDevice::choose_calibration_style() {
  int styles = 0;
  api_.hdGetIntegerv(hd::kCalibrationStyle, &styles);
  if (!hd_error("hdGetIntegerv(HD_CALIBRATION_STYLE)").empty()) styles = 0;
  cal_style_ = (styles & int(hd::kCalibrationAuto))      ? hd::kCalibrationAuto
               : (styles & int(hd::kCalibrationInkwell)) ? hd::kCalibrationInkwell
                                                         : 0;
}

/// Scheduler thread, inside a frame: until the device says its calibration is ok, update it
/// in the chosen style whenever it needs an update (NEEDS_MANUAL_INPUT: the user puts the
/// stylus in its inkwell; the next frames see NEEDS_UPDATE). True once calibrated.
bool OpenHapticsDevice::calibrate_in_frame() {
  if (calibrated_.load(std::memory_order_relaxed)) return true;
  const HDenum cal = api_.hdCheckCalibration();
  if (cal == hd::kCalibrationNeedsUpdate && cal_style_ != 0) {
    api_.hdUpdateCalibration(cal_style_);
    calibration_updates_.fetch_add(1, std::memory_order_relaxed);
  }
  if (cal == hd::kCalibrationOk) calibrated_.store(true, std::memory_order_relaxed);
  return cal == hd::kCalibrationOk;
}

void OpenHapticsDevice::open() {
  if (running_) return;
  if (api_.lib.handle == nullptr)
    if (const std::string e = load_hd_api(api_); !e.empty()) throw std::runtime_error("--haptic openhaptics: " + e);
  const std::string who = "openhaptics:" + (name_.empty() ? std::string("default") : name_);
  hhd_ = api_.hdInitDevice(name_.empty() ? hd::kDefaultDevice : name_.c_str());
  if (const std::string e = hd_error("hdInitDevice"); !e.empty() || hhd_ == hd::kInvalidHandle)
    throw std::runtime_error(who + ": " + (e.empty() ? "hdInitDevice returned HD_INVALID_HANDLE" : e));
  api_.hdMakeCurrentDevice(hhd_);
  read_caps();
  api_.hdEnable(hd::kForceOutput);
  enabled_output_ = true;
  reset_device_thread(sdk_now_ns());
  sched_ = api_.hdScheduleAsynchronous(&OpenHapticsDevice::callback, this, hd::kMaxSchedulerPriority);
  api_.hdStartScheduler();
  if (const std::string e = hd_error("hdStartScheduler"); !e.empty()) {
    api_.hdUnschedule(sched_);
    api_.hdDisableDevice(hhd_);
    throw std::runtime_error(who + ": " + e);
  }
  running_ = true;
  for (int i = 0; i < 1000 && frames_.load() == 0; ++i) sleep_ms(1);
  if (frames_.load() == 0) {
    close();
    throw std::runtime_error(who + ": the HD scheduler did not call back within 1 s");
  }
}

void OpenHapticsDevice::close() {
  if (!running_) return;
  // The callback applies an exact zero from here on; wait for two frames of it.
  closing_ = true;
  const long z0 = zero_frames_.load();
  for (int i = 0; i < 100 && zero_frames_.load() < z0 + 2; ++i) sleep_ms(1);
  api_.hdStopScheduler();
  api_.hdUnschedule(sched_);
  api_.hdDisable(hd::kForceOutput);
  api_.hdDisableDevice(hhd_);
  running_ = false;
}

std::string OpenHapticsDevice::last_error() const {
  const HDerror e = last_error_.load();
  return e == hd::kSuccess ? std::string() : error_text(e, 0);
}

std::string OpenHapticsDevice::sdk_status() const {
  const std::string last = last_error();
  return std::to_string(frames()) + " HD scheduler frames, " + std::to_string(errors()) + " HD errors" +
         (last.empty() ? "" : " (last: " + last + ")");
}

HDCallbackCode OpenHapticsDevice::callback(void* self) { return static_cast<OpenHapticsDevice*>(self)->tick(); }

HDCallbackCode OpenHapticsDevice::tick() {
  // The HD scheduler's thread, once per servo period of the device (1 kHz).
  const std::int64_t now = sdk_now_ns();
  double p[3] = {}, f[3] = {};
  int buttons = 0;
  api_.hdBeginFrame(hhd_);
  api_.hdGetDoublev(hd::kCurrentPosition, p);
  api_.hdGetIntegerv(hd::kCurrentButtons, &buttons);
  const bool calibrated = calibrate_in_frame();
  bool on = false;
  // The stall is judged at the clock of this look, after the frame's reads (a stall that came
  // due during them is acted on in this frame, not the next).
  const Vec3 force = force_now(sdk_now_ns(), on);
  // down: the last frame lost the device; not calibrated: the pose is not where it reads.
  const bool zero = closing_.load() || !on || down_ || !calibrated;
  if (!zero) device_to_hd_force(force, f);
  api_.hdSetDoublev(hd::kCurrentForce, f);
  api_.hdEndFrame(hhd_);
  if (zero) zero_frames_.fetch_add(1);
  const HDErrorInfo e = api_.hdGetError();
  DeviceReading r;
  r.position_m = hd_to_device_m(p);
  r.buttons = std::uint32_t(buttons);
  r.force_off = !enabled_output_ || !calibrated;
  // Zero force, not a fault (calibrating after the start is expected); the servo ramps in once
  // calibrated.
  if (!calibrated) r.status = DeviceStatus::kUncalibrated;
  if (e.errorCode != hd::kSuccess) {
    errors_.fetch_add(1);
    last_error_.store(e.errorCode);
    // A device error: the device is gone (the next frames send zero, the servo holds);
    // a force error: the device's own limit tripped (fault: the servo restarts, ramps in).
    r.status = hd::is_device_error(e.errorCode) ? DeviceStatus::kDisconnected : DeviceStatus::kFault;
  }
  down_ = r.status == DeviceStatus::kDisconnected;
  publish(r, now);
  frames_.fetch_add(1);
  return hd::kCallbackContinue;
}

}  // namespace isotouch::servo

namespace isotouch::servo {
std::string list_openhaptics(const HdApi& a) {
  const HHD h = a.hdInitDevice(hd::kDefaultDevice);
  const HDErrorInfo e = a.hdGetError();
  if (e.errorCode != hd::kSuccess || h == hd::kInvalidHandle)
    return "default device: none (hdInitDevice: " + error_text(e.errorCode, e.internalErrorCode) + ")";
  a.hdMakeCurrentDevice(h);
  const char* model = a.hdGetString(hd::kDeviceModelType);
  const char* serial = a.hdGetString(hd::kDeviceSerialNumber);
  const HDenum cal = a.hdCheckCalibration();
  std::string line = std::string("default device: ") + (model ? model : "?") + ", serial " + (serial ? serial : "?") +
                     ", calibration " + (cal == hd::kCalibrationOk ? "ok" : "not ok");
  a.hdDisableDevice(h);
  return line;
}
}  // namespace isotouch::servo
