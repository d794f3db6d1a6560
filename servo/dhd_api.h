// dhd_api.h - the subset of the Force Dimension SDK's DHD API (libdhd.so) isotouch calls,
// declared here so that the build needs no SDK header. Signatures and constants as the
// vendor's own dhdc.h declares them ("DHD - Haptic SDK ... (C) Force Dimension"):
//   github.com/WPI-AIM/ambf, external/DHD/include/dhdc.h at commit
//   772ae683005ce3cf9d6b9b90dbfb0facdb68844b (SDK 3.7.0-pre), and
//   github.com/BezniF/fdo6, include/dhdc.h at commit 6dde728f270d34edbafc795672ddb5069c3193d2
//   (SDK 3.10.0); identical for every declaration below. Device types newer than those
//   headers (lambda, sigma.3) and DHD_MAX_STATUS 17 as CHAI3D declares them for loading the
//   SDK at run time: github.com/chai3d/chai3d, src/devices/CDeltaDevices.cpp at commit
//   7c76b1f2dbe11ef5a3d3cbd7ef3286ff720b7a2d (the DHD_* constants and function pointers of its
//   WIN32 branch, cDeltaDevice::open()'s specifications table), matching
//   github.com/EmDash00/forcedimension_core-python, forcedimension_core/dhd/constants.py at
//   68c6a6f87bfd3147a7b43e7c649c2bc9b1786509 (bindings for SDK 3.14-3.16).
// The vendor header gives every device call a defaulted last argument `char ID = -1` (the
// default device) and, on Windows only, the __stdcall convention (__SDK); on Linux __SDK is
// empty, so these plain function pointers match. Conventions: every call returns >= 0 on
// success and -1 on error (dhdErrorGetLast() then says which kErr* value); some return the
// positive non-error values kTimeGuard or kMotorSaturated. Units: positions m, forces N.
// Frame: x toward the user, y right, z up, origin at the workspace's centre.
#pragma once

extern "C" {
typedef int (*DhdGetDeviceCount)(void);
typedef int (*DhdOpen)(void);  // the first available device; returns its ID or -1
typedef int (*DhdOpenID)(char id);
typedef int (*DhdClose)(char id);
typedef int (*DhdStop)(char id);  // disables forces and puts the device in BRAKE mode
typedef int (*DhdGetComMode)(char id);  // a kComMode* value or -1; "added in release 3.3.2"
typedef int (*DhdGetSystemType)(char id);
typedef int (*DhdGetStatus)(int* status, char id);  // vendor: int status[DHD_MAX_STATUS]
typedef int (*DhdGetPosition)(double* px, double* py, double* pz, char id);
typedef unsigned int (*DhdGetButtonMask)(char id);
typedef int (*DhdSetForce)(double fx, double fy, double fz, char id);
typedef int (*DhdEnableForce)(unsigned char val, char id);  // vendor: uchar val (kOn / kOff)
typedef int (*DhdErrorGetLast)(void);             // a kErr* value
typedef const char* (*DhdErrorGetLastStr)(void);  // optional: not in CHAI3D's list (is in dhdc.h 3.7+)
// Expert SDK. dhdSetWatchdog/dhdGetWatchdog are declared in dhdc.h's "expert SDK" section,
// "added in release 3.3.2"; CHAI3D (commit above, cDeltaDevice::open()) calls
// dhdEnableExpertMode() and then dhdSetWatchdog(255, id). Unit of val: 125 us ("Set the
// watchdog duration in multiples of 125 microseconds on compatible devices. If the watchdog
// duration is exceeded before the device receives a new force command, the device firmware
// will disable forces ... A value of 0 disables the watchdog feature."
// forcedimension_core/dhd/expert.py at 1131974ba54b316700da2c437827c89dbe4d0770 of the
// bindings above, whose docs say they are adapted from the official SDK documentation).
typedef int (*DhdEnableExpertMode)(void);
typedef int (*DhdDisableExpertMode)(void);
typedef int (*DhdSetWatchdog)(unsigned char val, char id);
typedef int (*DhdGetWatchdog)(unsigned char* val, char id);
}

namespace isotouch::servo::dhd {
constexpr unsigned char kOn = 1, kOff = 0;  // DHD_ON, DHD_OFF
constexpr int kUndefined = -1;              // DHD_UNDEFINED
// Device types (dhdGetSystemType). Vendor names: DHD_DEVICE_OMEGA33 = omega.6 right,
// DHD_DEVICE_OMEGA331 = omega.7 right, DHD_DEVICE_SIGMA331 = sigma.7 right (dhdc.h 3.7/3.10);
// CHAI3D 2022 names them DHD_DEVICE_OMEGA6_RIGHT etc. Lambda/sigma.3 values: CHAI3D only.
constexpr int kDeviceNone = 0, kDelta3 = 63, kOmega3 = 33, kOmega6Right = 34, kOmega6Left = 36, kOmega7Right = 35,
              kOmega7Left = 37, kSigma7Right = 104, kSigma7Left = 105, kLambda7Right = 108, kLambda7Left = 109,
              kFalcon = 60;
// Not (yet) in dhd_system_caps()'s table: they get its default (omega.3) limits.
constexpr int kSigma3 = 206, kLambda3 = 203, kLambda6Right = 131, kLambda6Left = 132, kController = 81,
              kControllerHr = 82, kCustom = 91;
// Positive, non-error return values ("useful non-error, positive return values").
constexpr int kTimeGuard = 1, kMotorSaturated = 2;  // DHD_TIMEGUARD, DHD_MOTOR_SATURATED
// dhdErrorGetLast() values: enum dhd_errors, in this order (DHD_NO_ERROR = 0 ...);
// DHD_ERROR_NO_REGULATION first appears in the 3.10.0 header.
constexpr int kErrNone = 0, kErr = 1, kErrCom = 2, kErrDhcBusy = 3, kErrNoDriverFound = 4, kErrNoDeviceFound = 5,
              kErrNotAvailable = 6, kErrTimeout = 7, kErrGeometry = 8, kErrExpertModeDisabled = 9,
              kErrNotImplemented = 10, kErrOutOfMemory = 11, kErrDeviceNotReady = 12, kErrFileNotFound = 13,
              kErrConfiguration = 14, kErrInvalidIndex = 15, kErrDeprecated = 16, kErrNullArgument = 17,
              kErrRedundantFail = 18, kErrNotEnabled = 19, kErrDeviceInUse = 20, kErrInvalid = 21,
              kErrNoRegulation = 22;
// dhdGetComMode() values ("USB operation modes").
constexpr int kComModeSync = 0, kComModeAsync = 1, kComModeVirtual = 3, kComModeNetwork = 4;
// dhdGetStatus(): the status vector's length and the entries isotouch may read. DHD_MAX_STATUS
// is 16 in dhdc.h 3.7/3.10 and 17 in CHAI3D 2022 and the 3.14+ bindings; pass a buffer of 17.
// DHD_STATUS_FORCE 5, DHD_STATUS_FORCEOFFCAUSE 14 and the DHD_FORCEOFF_* causes checked again
// against github.com/BezniF/fdo6 include/dhdc.h at 6dde728f (SDK 3.10.0, "status codes",
// "causes for device FORCE OFF state"). status[kStatusForce]: 1 while forces are on. The
// firmware watchdog's trip turns forces off (cause kForceOffWatchdog); dhdEnableForce(DHD_ON)
// turns them on again (the bindings' setWatchdog: "the device firmware will disable forces").
constexpr int kMaxStatus = 17;
constexpr int kStatusPower = 0, kStatusConnected = 1, kStatusForce = 5, kStatusBrake = 6, kStatusError = 9,
              kStatusForceOffCause = 14;
// status[kStatusForceOffCause]: why forces were last turned off ("causes for device FORCE OFF
// state").
constexpr int kForceOffNone = 0, kForceOffButton = 1, kForceOffVelocity = 2, kForceOffWatchdog = 3,
              kForceOffSoftware = 4, kForceOffUsbDisconnect = 5, kForceOffDeadman = 6;
// dhdSetWatchdog duration: val x 125 us; 0 disables the watchdog; 255 (CHAI3D's choice) is the
// largest, 31.875 ms.
constexpr int kWatchdogUnitUs = 125;
constexpr unsigned char kWatchdogOff = 0, kWatchdogMax = 255;
}  // namespace isotouch::servo::dhd
