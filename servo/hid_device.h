// hid_device.h - haptic devices on USB HID through hidapi (hidraw backend): the link, the
// device list, and opening a device by VID:PID[:serial] or by path.
#pragma once
#include "isotouch/servo/core_names.h"
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/report_device.h"

namespace isotouch::servo {

/// One HID device as hidapi lists it.
struct HidInfo {
  std::uint16_t vid = 0, pid = 0;
  std::string serial, path, manufacturer, product;
  std::string protocol;  ///< a protocol isotouch speaks ("isotouch-v1", "polhem") or ""
};

/// Every HID device hidapi sees (empty without hidraw devices). @throws std::runtime_error
/// if hidapi cannot start.
std::vector<HidInfo> list_hid_devices();

/// "hid:VID:PID[:SERIAL]" (hex IDs) or "hid:PATH" (/dev/hidrawN) as a link. hidapi cannot
/// wait for a report apart from reading it: ReportDevice polls (the default
/// wait_readable(), kPollUs) and reads without waiting, so no call overlaps another.
class HidLink final : public ReportLink {
 public:
  /// `path` non-empty: open by path; else by vid:pid and serial ("" = the first).
  HidLink(std::uint16_t vid, std::uint16_t pid, std::string serial, std::string path);
  ~HidLink() override;
  std::string name() const override;
  std::string open() override;
  void close() override;
  int read(std::span<std::uint8_t> buf, int timeout_ms) override;
  bool write(std::span<const std::uint8_t> report) override;
  int get_feature(std::uint8_t id, std::span<std::uint8_t> buf) override;

 private:
  std::uint16_t vid_, pid_;
  std::string serial_, path_;
  void* dev_ = nullptr;  // hid_device*
};

/// Parses "VID:PID[:SERIAL]" or "PATH" (starts with '/') and opens the device with the
/// protocol its VID:PID names (by path: looked up in the device list), or with `protocol`
/// ("polhem": `--haptic polhem:...`) whatever its ID. The Polhem's 1234:0006 is the mbed HID
/// library's default ID, shared by other mbed gadgets: it is refused unless named. @throws
/// std::invalid_argument on a bad spec or an unknown protocol, std::runtime_error if it
/// cannot be opened (the message names it and says why: permissions, not present).
std::unique_ptr<ReportDevice> open_hid_device(const std::string& spec, int fifo_priority = 0,
                                              const std::string& protocol = "",
                                              hid::polhem::Config polhem_config = hid::polhem::kDefaultConfig);
/// `--haptic polhem:LINK[,config=v1|v3]` (parse_polhem_spec): a Polhem over USB HID, or
/// over isotouch-devemu's socket (LINK emu:SOCKET), with that configuration's kinematics.
/// @throws as open_hid_device.
std::unique_ptr<ReportDevice> open_polhem(const PolhemSpec& spec, int fifo_priority = 0);

}  // namespace isotouch::servo
