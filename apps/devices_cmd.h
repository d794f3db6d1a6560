// devices_cmd.h - `isotouch devices`: the Vulkan devices (for --device) and the HID devices
// (for --haptic hid:...), with the protocol isotouch speaks to each, if any.
#pragma once
#include <iosfwd>

#include "isotouch/apps/subcommand.h"

namespace isotouch::app {

/// Prints both lists. A Vulkan error is printed and the HID list still follows.
/// @return 0; 1 if neither list could be read.
int run_devices(std::ostream& out);

/// Adds `devices` to the top-level command line.
Subcommand add_devices_command(CLI::App& cli);

}  // namespace isotouch::app
