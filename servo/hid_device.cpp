#include "isotouch/servo/hid_device.h"
#include "isotouch/servo/hid_report.h"

#include <hidapi.h>

#include <cstdio>
#include <cwchar>
#include <stdexcept>

#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/socket_link.h"

namespace isotouch::servo {
namespace {
std::string narrow(const wchar_t* w) {
  std::string s;
  if (!w) return s;
  for (; *w; ++w) s += (*w >= 0x20 && *w < 0x7f) ? char(*w) : '?';
  return s;
}
std::wstring widen(const std::string& s) { return std::wstring(s.begin(), s.end()); }
void init_hidapi() {
  if (hid_init() != 0) throw std::runtime_error("hidapi: hid_init failed");
}
std::string hex4(std::uint16_t v) {
  char b[8];
  std::snprintf(b, sizeof(b), "%04x", v);
  return b;
}
/// A hex USB ID (1 to 4 digits). @throws std::invalid_argument naming `what`.
std::uint16_t parse_id(const std::string& text, const char* what, const std::string& spec) {
  std::size_t used = 0;
  unsigned long v = 0;
  try {
    v = std::stoul(text, &used, 16);
  } catch (const std::exception&) {
    used = 0;
  }
  if (text.empty() || text.size() > 4 || used != text.size())
    throw std::invalid_argument("--haptic hid:" + spec + ": " + what + " '" + text + "' is not a hex USB ID (1 to 4 digits)");
  return std::uint16_t(v);
}
}  // namespace

std::vector<HidInfo> list_hid_devices() {
  init_hidapi();
  std::vector<HidInfo> out;
  hid_device_info* all = hid_enumerate(0, 0);
  for (hid_device_info* d = all; d; d = d->next) {
    HidInfo i;
    i.vid = d->vendor_id, i.pid = d->product_id;
    i.serial = narrow(d->serial_number), i.path = d->path ? d->path : "";
    i.manufacturer = narrow(d->manufacturer_string), i.product = narrow(d->product_string);
    i.protocol = protocol_name(i.vid, i.pid);
    out.push_back(i);
  }
  hid_free_enumeration(all);
  return out;
}

HidLink::HidLink(std::uint16_t vid, std::uint16_t pid, std::string serial, std::string path)
    : vid_(vid), pid_(pid), serial_(std::move(serial)), path_(std::move(path)) {}

HidLink::~HidLink() { close(); }

std::string HidLink::name() const {
  return path_.empty() ? "hid:" + hex4(vid_) + ":" + hex4(pid_) + (serial_.empty() ? "" : ":" + serial_) : "hid:" + path_;
}

std::string HidLink::open() {
  close();
  init_hidapi();
  if (!path_.empty()) dev_ = hid_open_path(path_.c_str());
  else {
    const std::wstring ws = widen(serial_);
    dev_ = hid_open(vid_, pid_, serial_.empty() ? nullptr : ws.c_str());
  }
  if (!dev_) return "cannot open the HID device (not plugged in, or no permission on /dev/hidraw*: see a udev rule)";
  return {};
}

void HidLink::close() {
  if (dev_) hid_close(static_cast<hid_device*>(dev_));
  dev_ = nullptr;
}

int HidLink::read(std::span<std::uint8_t> buf, int timeout_ms) {
  if (!dev_) return -1;
  return hid_read_timeout(static_cast<hid_device*>(dev_), buf.data(), buf.size(), timeout_ms);
}

bool HidLink::write(std::span<const std::uint8_t> report) {
  if (!dev_) return false;
  return hid_write(static_cast<hid_device*>(dev_), report.data(), report.size()) >= 0;
}

int HidLink::get_feature(std::uint8_t id, std::span<std::uint8_t> buf) {
  if (!dev_ || buf.empty()) return -1;
  buf[0] = id;
  return hid_get_feature_report(static_cast<hid_device*>(dev_), buf.data(), buf.size());
}

std::unique_ptr<ReportDevice> open_hid_device(const std::string& spec, int fifo_priority, const std::string& protocol,
                                              hid::polhem::Config polhem_config) {
  std::uint16_t vid = 0, pid = 0;
  std::string serial, path;
  if (!spec.empty() && spec[0] == '/') {
    path = spec;
    bool found = false;
    for (const HidInfo& i : list_hid_devices())
      if (i.path == path) vid = i.vid, pid = i.pid, found = true;
    if (!found) throw std::runtime_error("--haptic " + std::string(protocol.empty() ? "hid" : protocol) + ":" + spec + ": no HID device at this path (isotouch devices lists them)");
  } else {
    const std::size_t a = spec.find(':');
    if (a == std::string::npos) throw std::invalid_argument("--haptic hid:" + spec + ": expected VID:PID[:SERIAL] or a /dev/hidraw path");
    const std::size_t b = spec.find(':', a + 1);
    vid = parse_id(spec.substr(0, a), "vendor ID", spec);
    pid = parse_id(spec.substr(a + 1, b == std::string::npos ? std::string::npos : b - a - 1), "product ID", spec);
    if (b != std::string::npos) serial = spec.substr(b + 1);
  }
  const std::string kind = protocol == "polhem" ? "polhem" : "hid";
  // 1234:0006 is the mbed HID library's default ID: any mbed gadget with 14-byte reports has
  // it, and driving one as a Polhem would put currents on its pins. The user names it.
  if (protocol.empty() && vid == hid::polhem::kVid && pid == hid::polhem::kPid)
    throw std::invalid_argument("--haptic hid:" + spec + ": " + hex4(vid) + ":" + hex4(pid) +
                                " is the mbed HID library's default USB ID, not only the Polhem's: if this is a Polhem, "
                                "say so: --haptic polhem:" + spec);
  std::unique_ptr<DeviceProtocol> p =
      kind == "polhem" ? std::make_unique<PolhemProtocol>(polhem_config) : protocol_for(vid, pid);
  if (!p)
    throw std::invalid_argument("--haptic hid:" + spec + ": no known protocol for " + hex4(vid) + ":" + hex4(pid) +
                                " (known: isotouch protocol v1 " + hex4(kV1Vid) + ":" + hex4(kV1Pid) +
                                "; a Polhem: --haptic polhem:VID:PID)");
  ReportDeviceOptions o;
  o.fifo_priority = fifo_priority;
  auto dev = std::make_unique<ReportDevice>(std::make_unique<HidLink>(vid, pid, serial, path), std::move(p), o);
  dev->open();
  return dev;
}

std::unique_ptr<ReportDevice> open_polhem(const PolhemSpec& spec, int fifo_priority) {
  if (spec.link.rfind("emu:", 0) != 0) return open_hid_device(spec.link, fifo_priority, "polhem", spec.config);
  ReportDeviceOptions o;
  o.fifo_priority = fifo_priority;
  auto dev = std::make_unique<ReportDevice>(std::make_unique<SocketLink>(spec.link.substr(4)),
                                            std::make_unique<PolhemProtocol>(spec.config), o);
  dev->open();
  return dev;
}

}  // namespace isotouch::servo
