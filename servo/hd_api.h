// hd_api.h - the subset of the OpenHaptics HD API (libHD.so) isotouch calls, declared here so
// that the build needs no SDK header. Types, constants and signatures as the vendor's own
// headers declare them (SensAble/3D Systems, "Copyright (c) 2004 SensAble Technologies"):
//   github.com/danepowell/openhaptics at commit f7fef1bb6c0d3b017742bf3cda5a2a285d616b02, a
//   repackaged OpenHaptics 3.0 (build 66) Linux SDK: usr/include/HD/hdDefines.h (types,
//   HDErrorInfo, every constant below), usr/include/HD/hdDevice.h (device, calibration calls),
//   usr/include/HD/hdScheduler.h (HDCallbackCode, HDSchedulerHandle, HDSchedulerCallback,
//   scheduler calls), usr/include/HD/hdExport.h (calling conventions);
//   cross-checked against github.com/hhmai/PhantomAPI include/HD/hdDefines.h at commit
//   e01998cb43cf04cdafa7595392b3a352ce7f4941 (same header, HD_VERSION_MINOR_NUMBER 30):
//   every value here is identical in both.
// Not from pyOpenHaptics (github.com/mikelitu/pyOpenHaptics, pyOpenHaptics/hd_define.py at
// 73b3a188a03c1d4d22c9ad803f9be2d1c4365b68): it has HD_INVALID_OPERATION = 0x0103 and no
// HD_INVALID_INPUT_TYPE; the vendor header has HD_INVALID_OPERATION 0x0102 and
// HD_INVALID_INPUT_TYPE 0x0103.
// Calling convention: hdExport.h defines HDAPIENTRY as __attribute__((stdcall)) on linux and
// HDCALLBACK as empty; stdcall is ignored on x86-64, so the plain function pointers isotouch
// declares match there (a 32-bit x86 build would need the attribute).
// Scheduler use as OpenHaptics' own examples (usr/share/3DTouch/examples/HD/console/*, same
// repo and commit) and CHAI3D/iMSTK do: hdScheduleAsynchronous with a callback returning
// HD_CALLBACK_CONTINUE, hdBeginFrame/hdEndFrame around the reads and the force. Units of the HD
// API: positions mm, velocities mm/s, forces N, stiffness N/mm, damping N s/mm; frame: x right,
// y up, z toward the user (facing the device).
#pragma once
#include <cstdint>

extern "C" {
typedef int HDint;
typedef unsigned int HDuint;
typedef double HDdouble;
typedef unsigned int HDerror;
typedef unsigned int HDenum;
typedef unsigned int HHD;
typedef unsigned int HDCallbackCode;       // hdScheduler.h
typedef unsigned long HDSchedulerHandle;   // hdScheduler.h
typedef unsigned short HDushort;
typedef const char* HDstring;
typedef struct {
  HDerror errorCode;      // the HD_ error code
  int internalErrorCode;  // the original internal device-generated error
  HHD hHD;                // the current device's handle when the error occurred
} HDErrorInfo;
typedef HDCallbackCode (*HDSchedulerCallback)(void* pUserData);
// hdDevice.h, "Calibration routines":
//   HDAPI HDenum HDAPIENTRY hdCheckCalibration();
//   HDAPI void HDAPIENTRY hdUpdateCalibration(HDenum style);
// hdCheckCalibration returns one of the kCalibrationOk/NeedsUpdate/NeedsManualInput values;
// hdUpdateCalibration takes ONE style bit (kCalibrationEncoderReset/Auto/Inkwell). The SDK's
// Calibration example (usr/share/3DTouch/examples/HD/console/Calibration/Calibration.c, repo
// and commit above) reads the supported styles with hdGetIntegerv(HD_CALIBRATION_STYLE, &mask),
// prefers AUTO over INKWELL over ENCODER_RESET, calls hdUpdateCalibration for ENCODER_RESET
// before hdStartScheduler (device held at its reset position), and otherwise, with the
// scheduler running, calls hdUpdateCalibration(style) from a scheduler callback when
// hdCheckCalibration() == HD_CALIBRATION_NEEDS_UPDATE (NEEDS_MANUAL_INPUT: the user must put
// the stylus in the inkwell).
typedef HDenum (*HdCheckCalibration)(void);
typedef void (*HdUpdateCalibration)(HDenum style);
}

namespace isotouch::servo::hd {
constexpr HDCallbackCode kCallbackDone = 0, kCallbackContinue = 1;  // HD_CALLBACK_DONE / _CONTINUE
// Error codes (hdDefines.h "Error codes").
constexpr HDerror kSuccess = 0x0000;
// Function errors (pyOpenHaptics' kInvalidOperation, 0x0103, is HD_INVALID_INPUT_TYPE).
constexpr HDerror kInvalidEnum = 0x0100, kInvalidValue = 0x0101, kInvalidOperation = 0x0102,
                  kInvalidInputType = 0x0103, kBadHandle = 0x0104;
// Force errors.
constexpr HDerror kWarmMotors = 0x0200, kExceededMaxForce = 0x0201, kExceededMaxForceImpulse = 0x0202,
                  kExceededMaxVelocity = 0x0203, kForceError = 0x0204;
// Device errors.
constexpr HDerror kDeviceFault = 0x0300, kDeviceAlreadyInitiated = 0x0301, kCommError = 0x0302,
                  kCommConfigError = 0x0303, kTimerError = 0x0304;
// Haptic rendering context, scheduler, licensing errors.
constexpr HDerror kIllegalBegin = 0x0400, kIllegalEnd = 0x0401, kFrameError = 0x0402;
constexpr HDerror kInvalidPriority = 0x0500, kSchedulerFull = 0x0501, kInvalidLicense = 0x0600;
// hdGet* parameters.
constexpr HDenum kCurrentButtons = 0x2000, kCurrentPosition = 0x2050, kCurrentVelocity = 0x2051;
constexpr HDenum kDeviceModelType = 0x2501, kDeviceVendor = 0x2503, kDeviceSerialNumber = 0x2504;
constexpr HDenum kUsableWorkspaceDimensions = 0x2551, kInputDof = 0x2553, kOutputDof = 0x2554;
/// HD_CALIBRATION_STYLE: hdGetIntegerv, 1 int, the bitmask of the calibration styles the
/// device supports (kCalibrationEncoderReset | kCalibrationAuto | kCalibrationInkwell).
constexpr HDenum kCalibrationStyle = 0x2555;
constexpr HDenum kUpdateRate = 0x2600, kNominalMaxStiffness = 0x2602, kNominalMaxForce = 0x2603,
                 kNominalMaxDamping = 0x2609;
/// HD_NOMINAL_MAX_CONTINUOUS_FORCE: hdGetDoublev, 1 double [N]. The force the device can
/// sustain continuously (over a period of time) without its motors overheating, as opposed to
/// HD_NOMINAL_MAX_FORCE (0x2603), the peak force with the motors at room temperature. The SDK's
/// PreventWarmMotors example (usr/share/3DTouch/examples/HD/console/PreventWarmMotors/
/// PreventWarmMotors.c, repo and commit above) ramps its force clamp down toward this value
/// when HD_MOTOR_TEMPERATURE exceeds 0.7: "SensAble claims that the device can operate
/// continuously at that force without overheating."
constexpr HDenum kNominalMaxContinuousForce = 0x2604;
/// HD_MOTOR_TEMPERATURE: hdGetDoublev, one double per motor (HD_OUTPUT_DOF of them), each
/// "normalized between room temperature and the overheat temperature" (PreventWarmMotors.c).
constexpr HDenum kMotorTemperature = 0x2605;
constexpr HDenum kCurrentForce = 0x2700;  // hdSetDoublev: 3 doubles [N]
constexpr HDenum kForceOutput = 0x4000;   // hdEnable / hdDisable
constexpr HDushort kMaxSchedulerPriority = 0xFFFF;  // HD_MAX_SCHEDULER_PRIORITY = USHRT_MAX
// hdCheckCalibration return values ("Calibration return values").
constexpr HDenum kCalibrationOk = 0x5000, kCalibrationNeedsUpdate = 0x5001, kCalibrationNeedsManualInput = 0x5002;
// Calibration styles ("Calibration styles"; the vendor names are HD_CALIBRATION_ENCODER_RESET,
// HD_CALIBRATION_AUTO, HD_CALIBRATION_INKWELL - there are no HD_CALIBRATION_STYLE_* names).
constexpr HDenum kCalibrationEncoderReset = 1u << 0, kCalibrationAuto = 1u << 1, kCalibrationInkwell = 1u << 2;
constexpr HHD kInvalidHandle = 0xFFFFFFFFu;
constexpr const char* kDefaultDevice = nullptr;  // HD_DEFAULT_DEVICE (NULL)

/// "HD_COMM_ERROR (0x302)" and the like, for messages.
const char* error_name(HDerror code);
/// True for the device errors (0x300 range: fault, communication): the device is gone.
inline bool is_device_error(HDerror code) { return code >= 0x0300 && code < 0x0400; }
/// True for the force errors (0x200 range: the device's own safety tripped).
inline bool is_force_error(HDerror code) { return code >= 0x0200 && code < 0x0300; }
}  // namespace isotouch::servo::hd
