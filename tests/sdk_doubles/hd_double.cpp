// hd_double.cpp - a test double of the OpenHaptics HD library (built as libHD.so): the HD
// functions isotouch calls, with the SDK's units and conventions (positions mm, forces N,
// stiffness N/mm; x right, y up, z toward the user), its scheduler calling the scheduled
// callbacks on its own thread at 1 kHz, hdBeginFrame/hdEndFrame frames (a force set outside
// one, or a frame begun off the scheduler thread, raises an error), an error stack read by
// hdGetError, and a device that vanishes (HD_COMM_ERROR on every frame). Declarations from
// isotouch/servo/hd_api.h (types and signatures only); the constants' values below.
// Test controls: hdDouble* below. Environment: HD_DOUBLE_PATH, HD_DOUBLE_LOG (double_device.h),
// HD_DOUBLE_CALIBRATION=update (hdCheckCalibration says it needs an update until
// hdUpdateCalibration is called with a style the device offers, from the scheduler thread),
// =manual (it needs manual input until hdDoubleInkwell(), then an update), =never (it never
// gets ok); HD_DOUBLE_STYLES: the HD_CALIBRATION_STYLE mask (default 6: auto and inkwell).
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>

#include "isotouch/servo/hd_api.h"
#include "isotouch/tests/sdk_doubles/double_device.h"

// The vendor's values, written out here rather than taken from isotouch's hd_api.h, so that
// a wrong constant there cannot hide behind the same one here: OpenHaptics' hdDefines.h and
// hdScheduler.h (github.com/danepowell/openhaptics, usr/include/HD/, commit
// f7fef1bb6c0d3b017742bf3cda5a2a285d616b02; the same values in github.com/hhmai/PhantomAPI
// include/HD/hdDefines.h at e01998cb43cf04cdafa7595392b3a352ce7f4941).
namespace hd {
constexpr unsigned kSuccess = 0x0000;  // HD_SUCCESS
constexpr unsigned kInvalidEnum = 0x0100;  // HD_INVALID_ENUM
constexpr unsigned kInvalidOperation = 0x0102;  // HD_INVALID_OPERATION
constexpr unsigned kBadHandle = 0x0104;  // HD_BAD_HANDLE
constexpr unsigned kExceededMaxForce = 0x0201;  // HD_EXCEEDED_MAX_FORCE
constexpr unsigned kCommError = 0x0302;  // HD_COMM_ERROR
constexpr unsigned kDeviceAlreadyInitiated = 0x0301;  // HD_DEVICE_ALREADY_INITIATED
constexpr unsigned kCommConfigError = 0x0303;  // HD_COMM_CONFIG_ERROR
constexpr unsigned kIllegalBegin = 0x0400;  // HD_ILLEGAL_BEGIN
constexpr unsigned kIllegalEnd = 0x0401;  // HD_ILLEGAL_END
constexpr unsigned kCurrentButtons = 0x2000;  // HD_CURRENT_BUTTONS
constexpr unsigned kCurrentPosition = 0x2050;  // HD_CURRENT_POSITION
constexpr unsigned kCurrentVelocity = 0x2051;  // HD_CURRENT_VELOCITY
constexpr unsigned kDeviceModelType = 0x2501;  // HD_DEVICE_MODEL_TYPE
constexpr unsigned kDeviceVendor = 0x2503;  // HD_DEVICE_VENDOR
constexpr unsigned kDeviceSerialNumber = 0x2504;  // HD_DEVICE_SERIAL_NUMBER
constexpr unsigned kUsableWorkspaceDimensions = 0x2551;  // HD_USABLE_WORKSPACE_DIMENSIONS
constexpr unsigned kInputDof = 0x2553;  // HD_INPUT_DOF
constexpr unsigned kOutputDof = 0x2554;  // HD_OUTPUT_DOF
constexpr unsigned kCalibrationStyle = 0x2555;  // HD_CALIBRATION_STYLE
constexpr unsigned kUpdateRate = 0x2600;  // HD_UPDATE_RATE
constexpr unsigned kNominalMaxStiffness = 0x2602;  // HD_NOMINAL_MAX_STIFFNESS
constexpr unsigned kNominalMaxForce = 0x2603;  // HD_NOMINAL_MAX_FORCE
constexpr unsigned kNominalMaxContinuousForce = 0x2604;  // HD_NOMINAL_MAX_CONTINUOUS_FORCE
constexpr unsigned kNominalMaxDamping = 0x2609;  // HD_NOMINAL_MAX_DAMPING
constexpr unsigned kCurrentForce = 0x2700;  // HD_CURRENT_FORCE
constexpr unsigned kForceOutput = 0x4000;  // HD_FORCE_OUTPUT
constexpr unsigned kCalibrationOk = 0x5000;  // HD_CALIBRATION_OK
constexpr unsigned kCalibrationNeedsUpdate = 0x5001;  // HD_CALIBRATION_NEEDS_UPDATE
constexpr unsigned kCalibrationNeedsManualInput = 0x5002;  // HD_CALIBRATION_NEEDS_MANUAL_INPUT
constexpr unsigned kCalibrationAuto = 0x0002;  // HD_CALIBRATION_AUTO
constexpr unsigned kInvalidValue = 0x0101;  // HD_INVALID_VALUE
constexpr HDCallbackCode kCallbackDone = 0;  // HD_CALLBACK_DONE
constexpr HHD kInvalidHandle = 0xFFFFFFFFu;  // HD_INVALID_HANDLE
}  // namespace hd
using isotouch_double::DoubleDevice;

namespace {
// Isotouch's device frame (x right, y away from the user, z up) -> HD's [m].
DoubleDevice g_dev("HD_DOUBLE", [](double x, double y, double z) { return std::array<double, 3>{x, z, -y}; });
std::mutex g_mu;  // the error stack, the callbacks, the flags below
std::vector<HDerror> g_errors;
struct Scheduled {
  HDSchedulerCallback fn;
  void* data;
  HDSchedulerHandle handle;
};
std::vector<Scheduled> g_callbacks;
HDSchedulerHandle g_next_handle = 1;
bool g_inited = false, g_force_output = false;
std::thread g_scheduler;
std::atomic<bool> g_running{false};
std::atomic<long> g_illegal{0}, g_frames{0};
thread_local bool t_on_scheduler = false, t_in_frame = false;
thread_local double t_force[3];
thread_local bool t_force_set = false;
constexpr double kMaxForceN = 3.3, kMaxContinuousForceN = 0.88;
// The calibration state hdCheckCalibration reports (HD_DOUBLE_CALIBRATION sets the start).
std::atomic<unsigned> g_calibration{0};
std::atomic<long> g_calibration_updates{0}, g_calibration_updates_off_scheduler{0};
std::atomic<bool> g_never_calibrated{false};
unsigned calibration_at_start() {
  const char* c = std::getenv("HD_DOUBLE_CALIBRATION");
  g_never_calibrated = c && std::strcmp(c, "never") == 0;
  if (c && (std::strcmp(c, "update") == 0 || g_never_calibrated)) return hd::kCalibrationNeedsUpdate;
  if (c && std::strcmp(c, "manual") == 0) return hd::kCalibrationNeedsManualInput;
  return hd::kCalibrationOk;
}
int styles() {
  const char* s = std::getenv("HD_DOUBLE_STYLES");
  return s ? std::atoi(s) : 6;
}

void push_error(HDerror e) {
  std::lock_guard l(g_mu);
  g_errors.push_back(e);
  g_illegal.fetch_add(e == hd::kIllegalBegin || e == hd::kInvalidOperation ? 1 : 0);
}

void scheduler_loop() {
  t_on_scheduler = true;
  double next = isotouch_double::now_s();
  while (g_running.load()) {
    g_dev.step(0.001);
    std::vector<Scheduled> now;
    {
      std::lock_guard l(g_mu);
      now = g_callbacks;
    }
    for (const Scheduled& s : now)
      if (s.fn(s.data) == hd::kCallbackDone) {
        std::lock_guard l(g_mu);
        std::erase_if(g_callbacks, [&](const Scheduled& c) { return c.handle == s.handle; });
      }
    next += 0.001;
    const double wait = next - isotouch_double::now_s();
    if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
  }
}
}  // namespace

extern "C" {
HHD hdInitDevice(HDstring name) {
  if (name && std::strcmp(name, "Default Device") != 0 && std::strcmp(name, "PHANToM 1") != 0) {
    push_error(hd::kCommConfigError);  // no such device configuration
    return hd::kInvalidHandle;
  }
  {
    std::lock_guard l(g_mu);
    if (g_inited) {
      g_errors.push_back(hd::kDeviceAlreadyInitiated);
      return hd::kInvalidHandle;
    }
    g_inited = true;
  }
  g_calibration = calibration_at_start();
  g_dev.start();
  return 1;
}
void hdDisableDevice(HHD) {
  g_dev.write_log();
  std::lock_guard l(g_mu);
  g_inited = false;
}
void hdMakeCurrentDevice(HHD h) {
  if (h != 1) push_error(hd::kBadHandle);
}
void hdBeginFrame(HHD) {
  if (!t_on_scheduler) return push_error(hd::kIllegalBegin);
  t_in_frame = true, t_force_set = false;
}
void hdEndFrame(HHD) {
  if (!t_in_frame) return push_error(hd::kIllegalEnd);
  t_in_frame = false;
  g_frames.fetch_add(1);
  if (t_force_set) {
    double f[3] = {t_force[0], t_force[1], t_force[2]};
    bool on;
    {
      std::lock_guard l(g_mu);
      on = g_force_output;
    }
    if (std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) > kMaxForceN + 1e-9) {
      push_error(hd::kExceededMaxForce);  // the device's safety: no force this frame
      f[0] = f[1] = f[2] = 0;
    }
    g_dev.receive(f, on);
  }
  if (g_dev.vanished()) push_error(hd::kCommError);
}
HDErrorInfo hdGetError() {
  std::lock_guard l(g_mu);
  HDErrorInfo e{hd::kSuccess, 0, 1};
  if (!g_errors.empty()) e.errorCode = g_errors.back(), g_errors.pop_back();
  return e;
}
void hdGetDoublev(HDenum what, HDdouble* v) {
  const auto p = g_dev.position(), vel = g_dev.velocity();
  switch (what) {
    case hd::kCurrentPosition: for (int i = 0; i < 3; ++i) v[i] = p[i] * 1e3; return;   // mm
    case hd::kCurrentVelocity: for (int i = 0; i < 3; ++i) v[i] = vel[i] * 1e3; return;  // mm/s
    case hd::kNominalMaxForce: v[0] = kMaxForceN; return;
    case hd::kNominalMaxContinuousForce: v[0] = kMaxContinuousForceN; return;
    case hd::kNominalMaxStiffness: v[0] = 1.0; return;   // N/mm
    case hd::kNominalMaxDamping: v[0] = 0.005; return;   // N s/mm
    case hd::kUsableWorkspaceDimensions: {
      const double ws[6] = {-190, -130, -95, 190, 130, 95};  // mm: min x, y, z, max x, y, z
      std::memcpy(v, ws, sizeof ws);
      return;
    }
  }
  push_error(hd::kInvalidEnum);
}
void hdGetIntegerv(HDenum what, HDint* v) {
  switch (what) {
    case hd::kCurrentButtons: v[0] = 0; return;
    case hd::kOutputDof: v[0] = 3; return;
    case hd::kInputDof: v[0] = 6; return;
    case hd::kUpdateRate: v[0] = 1000; return;
    case hd::kCalibrationStyle: v[0] = styles(); return;
  }
  push_error(hd::kInvalidEnum);
}
HDstring hdGetString(HDenum what) {
  switch (what) {
    case hd::kDeviceModelType: return "PHANToM (test double)";
    case hd::kDeviceVendor: return "isotouch test double";
    case hd::kDeviceSerialNumber: return "DOUBLE-1";
  }
  push_error(hd::kInvalidEnum);
  return nullptr;
}
void hdSetDoublev(HDenum what, const HDdouble* v) {
  if (what != hd::kCurrentForce) return push_error(hd::kInvalidEnum);
  if (!t_in_frame) return push_error(hd::kInvalidOperation);  // forces only inside a frame
  std::memcpy(t_force, v, sizeof t_force);
  t_force_set = true;
}
void hdEnable(HDenum what) {
  if (what != hd::kForceOutput) return push_error(hd::kInvalidEnum);
  std::lock_guard l(g_mu);
  g_force_output = true;
}
void hdDisable(HDenum what) {
  if (what != hd::kForceOutput) return push_error(hd::kInvalidEnum);
  std::lock_guard l(g_mu);
  g_force_output = false;
}
void hdStartScheduler() {
  if (g_running.exchange(true)) return;
  g_scheduler = std::thread(scheduler_loop);
}
void hdStopScheduler() {
  if (!g_running.exchange(false)) return;
  g_scheduler.join();
}
HDSchedulerHandle hdScheduleAsynchronous(HDSchedulerCallback fn, void* data, HDushort) {
  std::lock_guard l(g_mu);
  g_callbacks.push_back({fn, data, g_next_handle});
  return g_next_handle++;
}
void hdUnschedule(HDSchedulerHandle h) {
  std::lock_guard l(g_mu);
  std::erase_if(g_callbacks, [&](const Scheduled& c) { return c.handle == h; });
}
HDenum hdCheckCalibration() { return g_calibration.load(); }
void hdUpdateCalibration(HDenum style) {
  g_calibration_updates.fetch_add(1);
  if (!t_on_scheduler) g_calibration_updates_off_scheduler.fetch_add(1);
  // One style bit the device offers; only an update that is needed takes.
  const bool one_bit = style != 0 && (style & (style - 1)) == 0;
  if (!one_bit || (int(style) & styles()) == 0) return push_error(hd::kInvalidValue);
  if (g_calibration.load() == hd::kCalibrationNeedsUpdate && !g_never_calibrated) g_calibration = hd::kCalibrationOk;
}

// Test controls.
void hdDoubleVanish(int on) { g_dev.vanish(on != 0); }
/// The user puts the stylus in its inkwell: a calibration that needed manual input needs an update.
void hdDoubleInkwell() {
  unsigned manual = hd::kCalibrationNeedsManualInput;
  g_calibration.compare_exchange_strong(manual, hd::kCalibrationNeedsUpdate);
}
long hdDoubleCalibrationUpdates() { return g_calibration_updates.load(); }
long hdDoubleCalibrationUpdatesOffScheduler() { return g_calibration_updates_off_scheduler.load(); }
/// HD_FORCE_OUTPUT as last set by hdEnable / hdDisable (1 on).
int hdDoubleForceOutput() {
  std::lock_guard l(g_mu);
  return g_force_output ? 1 : 0;
}
void hdDoubleSetTarget(const double mm[3]) {
  const double m[3] = {mm[0] * 1e-3, mm[1] * 1e-3, mm[2] * 1e-3};
  g_dev.set_target(m);
}
/// Copies up to `max` received forces as rows of 5 doubles (t_s, fx, fy, fz [N, HD frame],
/// flags: bit 0 output enabled, bit 1 vanished); returns how many there are.
int hdDoubleLog(double* out, int max) { return g_dev.copy_log(out, max); }
void hdDoubleClearLog() { g_dev.clear_log(); }
/// HD calls made against its conventions (a frame begun off the scheduler, a force set outside one).
long hdDoubleIllegalCalls() { return g_illegal.load(); }
long hdDoubleFrames() { return g_frames.load(); }
/// CLOCK_MONOTONIC of the log's 0 s [s].
double hdDoubleStartS() { return g_dev.start_s(); }
}
