// device_protocols.h - the report protocols a ReportDevice speaks: isotouch protocol v1
// (docs/hid-protocol.md) and the Polhem's USB HID reports (servo/hid_report.h).
#pragma once
#include "isotouch/servo/core_names.h"
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

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

/// The Polhem v1 (haptikfabriken): 14-byte reports without ID, encoder counts in, motor
/// currents out, the polhem_v1 kinematics on the host. No sequence numbers or timestamps.
/// Button 0: encoder d above 5000 (haptikfabrikenapi's convention). While the device flags
/// its calibration switch (info 1), the calibration command follows each of its reports (the
/// firmware keeps only its last queued report, so a command can be lost; upstream sends it in
/// place of a current command until the device stops asking).
class PolhemProtocol final : public DeviceProtocol {
 public:
  const char* name() const override { return "polhem"; }
  bool sequenced() const override { return false; }
  std::string handshake(ReportLink& link, DeviceCaps& caps) override;
  std::string decode_input(std::span<const std::uint8_t> bytes, DeviceReading& r) override;
  std::size_t encode_output(const Vec3& force_n, bool enable, std::uint64_t answers,
                            std::span<std::uint8_t> buf) override;
  std::size_t pending_command(std::span<std::uint8_t> buf) override;

 private:
  LatestValue<std::array<std::int16_t, 6>> encoders_;  // reader -> writer (the Jacobian's pose)
  bool calibrate_ = false;                              // reader thread: the last report asked
};

/// The protocol for a USB VID:PID, or null if none is known.
std::unique_ptr<DeviceProtocol> protocol_for(std::uint16_t vid, std::uint16_t pid);
/// "isotouch-v1", "polhem" or "" for a VID:PID.
std::string protocol_name(std::uint16_t vid, std::uint16_t pid);
/// isotouch protocol v1's USB IDs (pid.codes test VID; a device may use its own and be
/// opened with an explicit protocol).
constexpr std::uint16_t kV1Vid = 0x1209, kV1Pid = 0x0001;

}  // namespace isotouch::servo
