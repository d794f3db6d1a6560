#include "isotouch/servo/device_protocols.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>

#include "isotouch/servo/hid_report.h"

namespace isotouch::servo {

std::string V1Protocol::handshake(ReportLink& link, DeviceCaps& caps) {
  std::array<std::uint8_t, hid::kFeatureSize> buf{};
  const int n = link.get_feature(hid::kFeatureId, buf);
  if (n < 0) return "no capabilities feature report (is this an isotouch protocol v1 device?)";
  if (hid::Decoded d = hid::decode_caps(std::span(buf.data(), std::size_t(n)), caps); !d) return d.error;
  // A v1 device applies the newest force it was sent once per report period (its firmware's
  // loop, docs/hid-protocol.md): the servo may not run faster (ServoThread::start refuses).
  // A device declaring no rate (0) leaves the servo's rate unchecked.
  caps.output_rate_hz = caps.native_rate_hz;
  return {};
}

std::string V1Protocol::decode_input(std::span<const std::uint8_t> bytes, DeviceReading& r) {
  hid::InputReport in;
  if (hid::Decoded d = hid::decode(bytes, in); !d) return d.error;
  r.position_m = in.position_m;
  r.buttons = in.buttons;
  r.sequence = in.sequence;
  r.device_time_us = in.device_time_us;
  r.status = (in.flags & (hid::kFault | hid::kNotHomed)) ? DeviceStatus::kFault : DeviceStatus::kOk;
  r.force_off = !(in.flags & hid::kForceEnabled);
  r.watchdog_tripped = (in.flags & hid::kWatchdog) != 0;
  return {};
}

std::size_t V1Protocol::encode_output(const Vec3& force_n, bool enable, std::uint64_t answers,
                                      std::span<std::uint8_t> buf) {
  hid::OutputReport o;
  o.enable = enable;
  o.sequence = ++sequence_;
  o.answers = std::uint32_t(answers);
  o.force_n = force_n;
  const auto b = hid::encode(o);
  std::copy(b.begin(), b.end(), buf.begin());
  return b.size();
}

std::string PolhemProtocol::handshake(ReportLink& link, DeviceCaps& caps) {
  (void)link;  // the Polhem has no feature report: its capabilities are its configuration's
  caps = hid::polhem::caps(config_);
  mismatch_.clear();  // opened again: judged anew
  faulted_.store(false);
  // Opened or reconnected: it may have been powered up since (info 0, counters 0 wherever the
  // handle is), which no report shows. Calibrated again only by a command of ours.
  calibrated_.store(false);
  calibrate_ = commanded_ = false;
  return {};
}

std::string_view PolhemProtocol::fault() const {
  if (!mismatch_.empty()) return mismatch_;
  return calibrated_.load() ? std::string_view{} : kNotCalibrated;
}

std::string PolhemProtocol::decode_input(std::span<const std::uint8_t> bytes, DeviceReading& r) {
  hid::polhem::Input in;
  if (hid::Decoded d = hid::polhem::decode(bytes, in); !d) return d.error;
  encoders_.store(in.encoder);
  r.position_m = hid::polhem::position_m(in.encoder, config_);
  r.buttons = in.encoder[3] > 5000 ? 1u : 0u;
  // info 0 after our command: only a command clears the switch's flag, so the command ran
  // and these counts are the calibration's (encoders_ above holds them before the writer can
  // see calibrated_). info 0 without one proves nothing (the flag starts clear at power-up).
  if (in.info == 0 && commanded_) calibrated_.store(true), commanded_ = false;
  if (!calibrated_.load()) {
    // Uncalibrated counts: a wrong pose and a wrong Jacobian. No force until calibrated; not
    // a fault (the user calibrates when they will): the servo ramps in once it is.
    r.status = DeviceStatus::kUncalibrated;
    r.force_off = true;
  } else {
    r.force_off = false;  // the firmware drives what it is sent
    // Calibrated (it does not ask), a pose the configuration cannot give: the unit is of the
    // other one. Latched: its positions are wrong and its motors would push the wrong way.
    if (in.info == 0 && mismatch_.empty()) mismatch_ = hid::polhem::check_pose(r.position_m, config_);
    if (!mismatch_.empty()) faulted_.store(true);
    r.status = mismatch_.empty() ? DeviceStatus::kOk : DeviceStatus::kFault;
  }
  // Asked again after a command was sent: it was lost (the firmware keeps only the last
  // queued report), so it is sent again, once per report that asks, until it stops asking.
  calibrate_ = in.info == 1;
  return {};
}

std::size_t PolhemProtocol::encode_output(const Vec3& force_n, bool enable, std::uint64_t answers,
                                          std::span<std::uint8_t> buf) {
  (void)answers;  // the Polhem's reports carry no sequence
  // calibrated_ before encoders_: once it reads true, the counts are the calibrated ones.
  const bool on = enable && !faulted_.load() && calibrated_.load();
  const Vec3 amps = on ? hid::polhem::motor_currents_a(force_n, encoders_.load(), config_) : Vec3{};
  const auto b = hid::polhem::encode_currents(amps);
  buf[0] = 0;  // no report IDs: hidapi wants a leading 0
  std::copy(b.begin(), b.end(), buf.begin() + 1);
  return b.size() + 1;
}

std::size_t PolhemProtocol::pending_command(std::span<std::uint8_t> buf) {
  if (!calibrate_) return 0;
  calibrate_ = false;  // once per report that asks
  commanded_ = true;   // the next info 0 acknowledges it
  const auto b = hid::polhem::encode_calibrate(config_);
  buf[0] = 0;
  std::copy(b.begin(), b.end(), buf.begin() + 1);
  return b.size() + 1;
}

PolhemSpec parse_polhem_spec(const std::string& arg) {
  PolhemSpec s;
  const std::size_t comma = arg.find(',');
  s.link = arg.substr(0, comma);
  if (s.link.empty()) throw std::invalid_argument("--haptic polhem:" + arg + ": no device before the options");
  for (std::size_t at = comma; at != std::string::npos;) {
    const std::size_t next = arg.find(',', at + 1);
    const std::string opt = arg.substr(at + 1, next == std::string::npos ? std::string::npos : next - at - 1);
    const std::size_t eq = opt.find('=');
    const std::string key = opt.substr(0, eq), value = eq == std::string::npos ? "" : opt.substr(eq + 1);
    if (key != "config")
      throw std::invalid_argument("--haptic polhem:" + arg + ": unknown option '" + opt + "' (options: config=v1|v3)");
    if (!hid::polhem::parse_config(value, s.config))
      throw std::invalid_argument("--haptic polhem:" + arg + ": config '" + value + "' is neither v1 nor v3");
    at = next;
  }
  return s;
}

std::string polhem_config_note(const PolhemSpec& s) {
  const bool dflt = s.config == hid::polhem::kDefaultConfig;
  return std::string("kinematics ") + hid::polhem::config_name(s.config) +
         (dflt ? " (the default: upstream's USB example opens it; config=v1 for a polhem_v1)" : " (config=v1)") +
         ", from " + hid::polhem::kConfigSource;
}

std::unique_ptr<DeviceProtocol> protocol_for(std::uint16_t vid, std::uint16_t pid) {
  if (vid == kV1Vid && pid == kV1Pid) return std::make_unique<V1Protocol>();
  if (vid == hid::polhem::kVid && pid == hid::polhem::kPid) return std::make_unique<PolhemProtocol>();
  return nullptr;
}

std::string protocol_name(std::uint16_t vid, std::uint16_t pid) {
  if (vid == hid::polhem::kVid && pid == hid::polhem::kPid)
    return "polhem, if it is one (mbed's default ID: --haptic polhem:VID:PID)";
  const auto p = protocol_for(vid, pid);
  return p ? p->name() : "";
}

}  // namespace isotouch::servo
