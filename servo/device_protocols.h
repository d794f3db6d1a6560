// device_protocols.h - the report protocols a ReportDevice speaks: isotouch protocol v1
// (docs/hid-protocol.md) and the Polhem's USB HID reports (servo/hid_report.h).
#pragma once
#include "isotouch/servo/core_names.h"
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "isotouch/servo/hid_report.h"
#include "isotouch/servo/latest_value.h"
#include "isotouch/servo/report_device.h"

namespace isotouch::servo {

/// isotouch protocol v1: capabilities from feature report 3, input report 1, output report 2.
/// Input status flags: fault or not-homed -> DeviceStatus::kFault; force enabled clear ->
/// DeviceReading::force_off; watchdog -> DeviceReading::watchdog_tripped.
class V1Protocol final : public DeviceProtocol {
 public:
  const char* name() const override { return "isotouch-v1"; }
  std::string handshake(ReportLink& link, DeviceCaps& caps) override;
  std::string decode_input(std::span<const std::uint8_t> bytes, DeviceReading& r) override;
  std::size_t encode_output(const Vec3& force_n, bool enable, std::uint64_t answers,
                            std::span<std::uint8_t> buf) override;

 private:
  std::uint32_t sequence_ = 0;  // writer thread
};

/// The Polhem (haptikfabriken): 14-byte reports without ID, encoder counts in, motor
/// currents out, the kinematics of its configuration (polhem_v1 or polhem_v3) on the host.
/// No sequence numbers or timestamps. Button 0: encoder d above 5000 (haptikfabrikenapi's
/// convention).
///
/// Calibration. The firmware (forsslund/haptikfabrikenapi firmware/main.cpp) reports `info`
/// as a latched flag: 1 once its calibration switch closed, 0 again only after a calibration
/// command (command 1) set the counters. The flag starts at 0 at power-up and the counters at
/// 0 wherever the handle is, so info 0 alone does not mean calibrated; and the firmware drives
/// any currents it is sent. So the device counts as uncalibrated from handshake() (every open
/// and reconnect: it may have been power-cycled) until this protocol has itself sent the
/// command in answer to an info 1 and then seen info 0 (only the command clears the flag).
/// Until then every reading is DeviceStatus::kUncalibrated (zero force, not counted as a
/// fault; the servo ramps in once calibrated) with force_off set, fault() says to press
/// the handle into the switch, and encode_output() sends zero currents. While the device asks
/// (info 1) the command follows each of its reports (the firmware keeps only its last queued
/// report, so a command can be lost; upstream sends it in place of a current command until
/// the device stops asking). A calibrated unit docked again keeps its force meanwhile (its
/// counts stay valid until the new command runs). Not done: telling a switch latched before
/// the host connected (the command then sets the counters wherever the handle has gone) from
/// a live press, and checking that the acknowledging report's counts are the calibration pose.
///
/// Once calibrated, a position the configuration cannot give (hid::polhem::check_pose: the
/// unit is of the other configuration) faults the device until it is opened again: zero
/// current, and fault() says why.
class PolhemProtocol final : public DeviceProtocol {
 public:
  explicit PolhemProtocol(hid::polhem::Config config = hid::polhem::kDefaultConfig) : config_(config) {}
  const char* name() const override { return "polhem"; }
  bool sequenced() const override { return false; }
  std::string handshake(ReportLink& link, DeviceCaps& caps) override;
  std::string decode_input(std::span<const std::uint8_t> bytes, DeviceReading& r) override;
  std::size_t encode_output(const Vec3& force_n, bool enable, std::uint64_t answers,
                            std::span<std::uint8_t> buf) override;
  std::size_t pending_command(std::span<std::uint8_t> buf) override;
  /// The mismatch (latched), else the missing calibration, else "".
  std::string_view fault() const override;
  hid::polhem::Config config() const { return config_; }
  /// fault() while the device is not calibrated since handshake().
  static constexpr std::string_view kNotCalibrated =
      "Polhem: not calibrated since isotouch opened it: press the handle into its calibration switch";

 private:
  hid::polhem::Config config_;
  LatestValue<std::array<std::int16_t, 6>> encoders_;  // reader -> writer (the Jacobian's pose)
  std::atomic<bool> faulted_{false};                    // reader -> writer: no current
  std::atomic<bool> calibrated_{false};                 // reader -> writer: our command acknowledged
  bool calibrate_ = false;                              // reader thread: the last report asked
  bool commanded_ = false;                              // reader thread: a command sent since it last said info 0
  std::string mismatch_;                                // reader thread: why it faulted
};

/// `--haptic polhem:` parsed: "LINK[,config=v1|v3]", LINK a USB VID:PID[:SERIAL], a
/// /dev/hidrawN path or emu:SOCKET (isotouch-devemu --polhem).
struct PolhemSpec {
  std::string link;
  hid::polhem::Config config = hid::polhem::kDefaultConfig;
};
/// @throws std::invalid_argument naming the option and its value.
PolhemSpec parse_polhem_spec(const std::string& arg);
/// "kinematics polhem_v3 (default; from forsslund/hfabapi ...)": which configuration is
/// active and where it comes from, for the device's description.
std::string polhem_config_note(const PolhemSpec& s);

/// The protocol for a USB VID:PID, or null if none is known.
std::unique_ptr<DeviceProtocol> protocol_for(std::uint16_t vid, std::uint16_t pid);
/// "isotouch-v1", "polhem" or "" for a VID:PID.
std::string protocol_name(std::uint16_t vid, std::uint16_t pid);
/// isotouch protocol v1's USB IDs (pid.codes test VID; a device may use its own and be
/// opened with an explicit protocol).
constexpr std::uint16_t kV1Vid = 0x1209, kV1Pid = 0x0001;

}  // namespace isotouch::servo
