#include "isotouch/run/sdk_haptic_device.h"

#include <stdexcept>

#include "isotouch/servo/forcedimension_device.h"
#include "isotouch/servo/openhaptics_device.h"

namespace isotouch::run {
namespace {
int parse_index(const std::string& arg) {
  if (arg.empty()) return 0;
  std::size_t used = 0;
  int i = -1;
  try {
    i = std::stoi(arg, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != arg.size() || i < 0)
    throw std::invalid_argument("--haptic forcedimension:" + arg + ": the index '" + arg +
                                "' is not a device number (0 = the first)");
  return i;
}
}  // namespace

std::unique_ptr<servo::SdkDevice> open_sdk_device(const std::string& kind, const std::string& arg,
                                                  std::string& description) {
  if (kind == "openhaptics") {
    auto d = std::make_unique<servo::OpenHapticsDevice>(arg);
    d->open();
    description = d->description() + (d->warning().empty() ? "" : "; warning: " + d->warning());
    return d;
  }
  auto d = std::make_unique<servo::ForceDimensionDevice>(parse_index(arg));
  d->open();
  description = d->description();
  return d;
}

bool print_sdk_devices(std::ostream& out) {
  servo::HdApi hd;
  const std::string hd_error = servo::load_hd_api(hd);
  out << "OpenHaptics HD (--haptic openhaptics[:NAME]; override: ISOTOUCH_HD_LIBRARY):\n";
  if (!hd.lib) {
    out << "  SDK not found (searched: " << hd.lib.searched << ")\n";
  } else if (!hd_error.empty()) {
    out << "  SDK found at " << hd.lib.path << " but unusable: " << hd_error << "\n";
  } else {
    out << "  SDK found: " << hd.lib.path << "\n  " << servo::list_openhaptics(hd) << "\n";
  }
  servo::DhdApi dhd;
  const std::string dhd_error = servo::load_dhd_api(dhd);
  out << "Force Dimension (--haptic forcedimension[:INDEX]; override: ISOTOUCH_DHD_LIBRARY):\n";
  if (!dhd.lib) {
    out << "  SDK not found (searched: " << dhd.lib.searched << ")\n";
  } else if (!dhd_error.empty()) {
    out << "  SDK found at " << dhd.lib.path << " but unusable: " << dhd_error << "\n";
  } else {
    out << "  SDK found: " << dhd.lib.path << "\n";
    for (const std::string& line : servo::list_forcedimension(dhd)) out << "  " << line << "\n";
  }
  return hd.lib || dhd.lib;
}

}  // namespace isotouch::run
