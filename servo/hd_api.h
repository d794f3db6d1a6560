// hd_api.h - the subset of the OpenHaptics HD API (libHD.so) isotouch calls, declared here so
// that the build needs no SDK header. Types, constants and signatures as declared by
// pyOpenHaptics, which loads libHD.so at run time with ctypes:
//   github.com/mikelitu/pyOpenHaptics, pyOpenHaptics/hd_define.py at commit
//   73b3a188a03c1d4d22c9ad803f9be2d1c4365b68 (types, HDErrorInfo, every constant below) and
//   pyOpenHaptics/hd.py at d4d1ca4f0a116ba75595da24cd0e505a41fdf7e1 (signatures);
// the scheduler calls as CHAI3D's and iMSTK's callers use them (hdScheduleAsynchronous with a
// callback returning HD_CALLBACK_CONTINUE, hdBeginFrame/hdEndFrame around the reads and the
// force). Units of the HD API: positions mm, velocities mm/s, forces N, stiffness N/mm,
// damping N s/mm; frame: x right, y up, z toward the user (facing the device).
#pragma once
#include <cstdint>

extern "C" {
typedef int HDint;
typedef unsigned int HDuint;
typedef double HDdouble;
typedef unsigned int HDerror;
typedef unsigned int HDenum;
typedef unsigned int HHD;
typedef unsigned int HDCallbackCode;
typedef unsigned long HDSchedulerHandle;
typedef unsigned short HDushort;
typedef const char* HDstring;
typedef struct {
  HDerror errorCode;
  int internalErrorCode;
  HHD hHD;
} HDErrorInfo;
typedef HDCallbackCode (*HDSchedulerCallback)(void* pUserData);
}

namespace isotouch::servo::hd {
constexpr HDCallbackCode kCallbackDone = 0, kCallbackContinue = 1;  // HD_CALLBACK_DONE / _CONTINUE
// Error codes.
constexpr HDerror kSuccess = 0x000;
constexpr HDerror kInvalidEnum = 0x0100, kInvalidValue = 0x0101, kInvalidOperation = 0x0103, kBadHandle = 0x0104;
constexpr HDerror kWarmMotors = 0x0200, kExceededMaxForce = 0x0201, kExceededMaxForceImpulse = 0x0202,
                  kExceededMaxVelocity = 0x0203, kForceError = 0x0204;
constexpr HDerror kDeviceFault = 0x0300, kDeviceAlreadyInitiated = 0x0301, kCommError = 0x0302,
                  kCommConfigError = 0x0303, kTimerError = 0x0304;
constexpr HDerror kIllegalBegin = 0x0400, kIllegalEnd = 0x0401, kFrameError = 0x0402;
constexpr HDerror kInvalidPriority = 0x0500, kSchedulerFull = 0x0501, kInvalidLicense = 0x0600;
// hdGet* parameters.
constexpr HDenum kCurrentButtons = 0x2000, kCurrentPosition = 0x2050, kCurrentVelocity = 0x2051;
constexpr HDenum kDeviceModelType = 0x2501, kDeviceVendor = 0x2503, kDeviceSerialNumber = 0x2504;
constexpr HDenum kUsableWorkspaceDimensions = 0x2551, kInputDof = 0x2553, kOutputDof = 0x2554;
constexpr HDenum kUpdateRate = 0x2600, kNominalMaxStiffness = 0x2602, kNominalMaxForce = 0x2603,
                 kNominalMaxDamping = 0x2609;
constexpr HDenum kCurrentForce = 0x2700;  // hdSetDoublev: 3 doubles [N]
constexpr HDenum kForceOutput = 0x4000;   // hdEnable / hdDisable
constexpr HDushort kMaxSchedulerPriority = 0xFFFF;
constexpr HDenum kCalibrationOk = 0x5000, kCalibrationNeedsUpdate = 0x5001, kCalibrationNeedsManualInput = 0x5002;
constexpr HHD kInvalidHandle = 0xFFFFFFFFu;
constexpr const char* kDefaultDevice = nullptr;  // HD_DEFAULT_DEVICE

/// "HD_COMM_ERROR (0x302)" and the like, for messages.
const char* error_name(HDerror code);
/// True for the device errors (0x300 range: fault, communication): the device is gone.
inline bool is_device_error(HDerror code) { return code >= 0x0300 && code < 0x0400; }
/// True for the force errors (0x200 range: the device's own safety tripped).
inline bool is_force_error(HDerror code) { return code >= 0x0200 && code < 0x0300; }
}  // namespace isotouch::servo::hd
