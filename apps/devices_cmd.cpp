#include "isotouch/apps/devices_cmd.h"

#include <iostream>
#include <memory>

#include <cstdio>
#include <ostream>
#include <stdexcept>

#include "isotouch/servo/hid_device.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/run/device_check.h"
#include "isotouch/run/sdk_haptic_device.h"

namespace isotouch::app {
namespace {
std::string hex4(unsigned v) {
  char b[8];
  std::snprintf(b, sizeof(b), "%04x", v & 0xFFFFu);
  return b;
}

bool print_vulkan(std::ostream& out) {
  out << "Vulkan devices (--device NAME|INDEX):\n";
  auto devs = engine::VulkanContext::list_devices();
  if (!devs) {
    out << "  none: Vulkan: " << devs.error << "\n";
    return false;
  }
  for (std::size_t i = 0; i < devs.value->size(); ++i) {
    const auto& d = (*devs.value)[i];
    out << i << ": " << d.name << " (" << d.type << ", " << d.driver << ")\n";
  }
  return true;
}

bool print_hid(std::ostream& out) {
  out << "HID devices (--haptic hid:VID:PID[:SERIAL] or hid:PATH):\n";
  std::vector<servo::HidInfo> hid;
  try {
    hid = servo::list_hid_devices();
  } catch (const std::exception& e) {
    out << "  none: " << e.what() << "\n";
    return false;
  }
  if (hid.empty()) out << "  none (no /dev/hidraw* devices readable; isotouch-devemu: --haptic emu:SOCKET)\n";
  for (const servo::HidInfo& i : hid)
    out << "  " << hex4(i.vid) << ":" << hex4(i.pid) << "  serial '" << i.serial << "'  " << i.path << "  "
        << i.manufacturer << " " << i.product << "  protocol: "
        << (i.protocol.empty() ? "none known" : i.protocol) << "\n";
  return true;
}
}  // namespace

int run_devices(std::ostream& out) {
  const bool vk = print_vulkan(out);
  const bool hid = print_hid(out);
  const bool sdk = run::print_sdk_devices(out);
  return vk || hid || sdk ? 0 : 1;
}

Subcommand add_devices_command(CLI::App& cli) {
  CLI::App* d =
      cli.add_subcommand("devices", "List the Vulkan devices, the HID devices (VID:PID, serial, path, known protocol) and the vendor SDKs found (OpenHaptics, Force Dimension) with their devices");
  auto check = std::make_shared<run::DeviceCheckOptions>();
  d->add_option("--check", check->spec,
                "Check one device (openhaptics[:NAME], forcedimension[:INDEX], emu:SOCKET, hid:..., polhem:...): read its pose "
                "with force off, then ask before rendering a soft wall");
  d->add_option("--seconds", check->read_seconds, "--check: how long the pose is read [s] (default 5)")->check(CLI::PositiveNumber);
  d->add_option("--wall-seconds", check->wall_seconds, "--check: how long the wall is rendered [s] (default 10)")
      ->check(CLI::PositiveNumber);
  return {d, [check](const std::string&) {
            return check->spec.empty() ? run_devices(std::cout) : run::check_device(*check, std::cin, std::cout);
          }};
}

}  // namespace isotouch::app
