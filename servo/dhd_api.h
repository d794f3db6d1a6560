// dhd_api.h - the subset of the Force Dimension SDK's DHD API (libdhd.so) isotouch calls,
// declared here so that the build needs no SDK header. Signatures, constants and the per
// system type limits as CHAI3D declares them for loading the SDK at run time:
//   github.com/chai3d/chai3d, src/devices/CDeltaDevices.cpp at commit
//   7c76b1f2dbe11ef5a3d3cbd7ef3286ff720b7a2d (the function pointer declarations and
//   DHD_* constants of its WIN32 branch, cDeltaDevice::open()'s specifications table).
// Conventions: every call returns >= 0 on success and -1 on error; the last argument is
// the device ID dhdOpenID() returned. Units: positions m, forces N. Frame: x toward the
// user, y right, z up, origin at the workspace's centre.
#pragma once

extern "C" {
typedef int (*DhdGetDeviceCount)(void);
typedef int (*DhdOpenID)(char id);
typedef int (*DhdClose)(char id);
typedef int (*DhdGetSystemType)(char id);
typedef int (*DhdGetPosition)(double* px, double* py, double* pz, char id);
typedef unsigned int (*DhdGetButtonMask)(char id);
typedef int (*DhdSetForce)(double fx, double fy, double fz, char id);
typedef int (*DhdEnableForce)(unsigned char val, char id);
typedef const char* (*DhdErrorGetLastStr)(void);  // optional: not in CHAI3D's list
}

namespace isotouch::servo::dhd {
constexpr unsigned char kOn = 1, kOff = 0;  // DHD_ON, DHD_OFF
constexpr int kDeviceNone = 0, kDelta3 = 63, kOmega3 = 33, kOmega6Right = 34, kOmega6Left = 36, kOmega7Right = 35,
              kOmega7Left = 37, kSigma7Right = 104, kSigma7Left = 105, kLambda7Right = 108, kLambda7Left = 109,
              kFalcon = 60;
}  // namespace isotouch::servo::dhd
