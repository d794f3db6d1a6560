#include "isotouch/run/sdk_haptic_device.h"

#include <ostream>
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
/// Found, found but unusable, or not found (searched: ...); true if its devices can be listed.
bool print_sdk(const servo::SdkLibrary& lib, const std::string& error, std::ostream& out) {
  if (!lib) out << "  SDK not found (searched: " << lib.searched << ")\n";
  else if (!error.empty()) out << "  SDK found at " << lib.path << " but unusable: " << error << "\n";
  else out << "  SDK found: " << lib.path << "\n";
  return lib && error.empty();
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
  if (print_sdk(hd.lib, hd_error, out)) out << "  " << servo::list_openhaptics(hd) << "\n";
  servo::DhdApi dhd;
  const std::string dhd_error = servo::load_dhd_api(dhd);
  out << "Force Dimension (--haptic forcedimension[:INDEX]; override: ISOTOUCH_DHD_LIBRARY):\n";
  if (print_sdk(dhd.lib, dhd_error, out))
    for (const std::string& line : servo::list_forcedimension(dhd)) out << "  " << line << "\n";
  return hd.lib || dhd.lib;
}

}  // namespace isotouch::run
