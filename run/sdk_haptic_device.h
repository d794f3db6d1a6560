// sdk_haptic_device.h - the devices driven through a vendor SDK loaded at run time, for the
// `--haptic` factory and `isotouch devices`:
//   openhaptics[:NAME]       3D Systems Touch / Phantom through libHD.so (NAME: the device's
//                            configuration name; default: the default device)
//   forcedimension[:INDEX]   Force Dimension / Novint Falcon through libdhd.so (INDEX from 0)
#pragma once
#include <memory>
#include <ostream>
#include <string>

#include "isotouch/servo/sdk_device.h"

namespace isotouch::run {

/// Opens `kind` ("openhaptics" or "forcedimension") with `arg`; `description` gets the
/// device's line for the log (with its calibration warning, if any).
/// @throws std::invalid_argument on a bad argument, std::runtime_error if the SDK is
/// missing (naming what was searched) or the device cannot be opened (the SDK's error).
std::unique_ptr<servo::SdkDevice> open_sdk_device(const std::string& kind, const std::string& arg,
                                                  std::string& description);

/// `isotouch devices`: both SDKs, found or not (searched: ...), the override variables and
/// the devices each sees. Returns whether any SDK was found.
bool print_sdk_devices(std::ostream& out);

}  // namespace isotouch::run
