// hid_report.h - the HID reports of the devices isotouch drives: encode and decode only (no
// I/O). Our own protocol v1 (docs/hid-protocol.md) and the Polhem (WoodenHaptics /
// haptikfabriken) USB HID reports.
#pragma once
#include "isotouch/servo/core_names.h"
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "isotouch/servo/device_io.h"
#include "isotouch/core/vec3.h"

namespace isotouch::servo::hid {

// ---------------------------------------------------------------------------------------
// Protocol v1 (docs/hid-protocol.md). Little-endian; byte 0 is the report ID; the last two
// bytes are a CRC-16/CCITT-FALSE of the bytes before them.
// ---------------------------------------------------------------------------------------
constexpr std::uint8_t kVersion = 1;
constexpr std::uint8_t kInputId = 0x01;    ///< device -> host, every device period
constexpr std::uint8_t kOutputId = 0x02;   ///< host -> device, every servo tick
constexpr std::uint8_t kFeatureId = 0x03;  ///< capabilities (GET_FEATURE)
constexpr std::size_t kInputSize = 32, kOutputSize = 28, kFeatureSize = 64;
constexpr double kPositionUnitM = 1e-6;    ///< position: int32 micrometres
constexpr double kForceUnitN = 1e-3;       ///< force: int32 millinewtons

/// Input report status flags.
enum InputFlags : std::uint16_t {
  kForceEnabled = 1u << 0,  ///< the amplifiers are on
  kFault = 1u << 1,         ///< the device detected a fault (over-current, encoder error)
  kWatchdog = 1u << 2,      ///< no output report within the watchdog time: force zeroed
  kNotHomed = 1u << 3,      ///< position not calibrated yet (refused by the host)
};

/// Device -> host: one position sample.
struct InputReport {
  std::uint16_t flags = 0;
  std::uint32_t sequence = 0;        ///< +1 per report sent (wraps)
  std::uint32_t device_time_us = 0;  ///< the device's clock at sampling [us] (wraps)
  Vec3 position_m;                   ///< end effector, device frame [m]
  std::uint32_t buttons = 0;         ///< bit i: button i down
};

/// Host -> device: the force to render until the next report.
struct OutputReport {
  bool enable = false;       ///< false: the device zeroes its force and keeps reporting
  std::uint32_t sequence = 0;  ///< +1 per report the host sends (wraps)
  std::uint32_t answers = 0;   ///< the input sequence the force was computed from
  Vec3 force_n;              ///< device frame [N]
};

/// Why a report was refused ("" = accepted).
struct Decoded {
  std::string error;
  explicit operator bool() const { return error.empty(); }
};

std::array<std::uint8_t, kInputSize> encode(const InputReport& r);
/// Non-finite or out-of-range forces are encoded as zero with enable cleared.
std::array<std::uint8_t, kOutputSize> encode(const OutputReport& r);
/// Capabilities; the name is cut to 14 bytes.
std::array<std::uint8_t, kFeatureSize> encode_caps(const DeviceCaps& c);

/// Decoders: any bytes; a refused report says why (size, ID, version, CRC, range).
Decoded decode(std::span<const std::uint8_t> bytes, InputReport& out);
Decoded decode(std::span<const std::uint8_t> bytes, OutputReport& out);
Decoded decode_caps(std::span<const std::uint8_t> bytes, DeviceCaps& out);

std::uint16_t crc16(std::span<const std::uint8_t> bytes);

// ---------------------------------------------------------------------------------------
// Polhem (haptikfabriken / WoodenHaptics "PolhemUSB" firmware on an mbed LPC1768): USB HID
// VID 0x1234 PID 0x0006, reports without ID, 14 bytes each way, little-endian int16:
//   in:  encoder a, b, c, d, e, f [counts], info (1: calibration requested)
//   out: motor current a, b, c [mA], command (0: currents, 1: set encoders), attr 0..2
// The host computes position and motor currents with one of two kinematic configurations,
// polhem_v1 (the WoodenHaptics serial chain) or polhem_v3 (the Polhem's five-bar linkage),
// both taken from one upstream commit (kConfigSource). The firmware turns the motors off
// 0.5 s after the last output report.
// ---------------------------------------------------------------------------------------
namespace polhem {
constexpr std::uint16_t kVid = 0x1234, kPid = 0x0006;
constexpr std::size_t kReportSize = 14;
/// The host caps each motor's current here (ESCON 24/4): the whole vector is scaled down
/// until its largest component is at the cap (limit_currents_a), so the force keeps its direction.
constexpr double kMaxCurrentA = 2.0;

/// The kinematic configuration of the unit (haptikfabriken's Kinematics::configuration).
enum class Config { kV1, kV3 };
/// What the source commit's USB example opens (hfab_api.cpp: polhem_v3()).
constexpr Config kDefaultConfig = Config::kV3;
/// Where both configurations and their maths come from: repository, commit, date, files.
extern const char* const kConfigSource;
/// "polhem_v1" or "polhem_v3".
const char* config_name(Config c);
/// "v1", "v3", "polhem_v1" or "polhem_v3" -> `c`; false for anything else.
bool parse_config(const std::string& s, Config& c);
/// The counts a, b, c, d, e, f the calibration command sets (calibrate_enc_a..f): the
/// unit's calibration pose in its configuration's counts.
std::array<std::int16_t, 6> calibration_counts(Config c);

struct Input {
  std::array<std::int16_t, 6> encoder{};
  std::int16_t info = 0;
};
Decoded decode(std::span<const std::uint8_t> bytes, Input& out);
std::array<std::uint8_t, kReportSize> encode(const Input& in);
/// `amps` [A] scaled as one vector so that no motor's current exceeds `cap`: multiplied by
/// min over i of cap / |amps_i| where one exceeds it (the largest then exactly +-cap), else
/// unchanged. Clamping each motor on its own would turn the force (the currents are J^T F, linear
/// in F at a pose: scaling them scales F and keeps its direction). Any non-finite component:
/// all three zero.
Vec3 limit_currents_a(const Vec3& amps, double cap = kMaxCurrentA);
/// The 14 bytes of a current command: `amps` through limit_currents_a, rounded to mA.
std::array<std::uint8_t, kReportSize> encode_currents(const Vec3& amps);
/// The calibration command: sets the encoder counters to calibration_counts(c) (a-c in
/// attr 0-2, d-f in the current fields, as upstream sends it).
std::array<std::uint8_t, kReportSize> encode_calibrate(Config c);
/// Decodes an output report's currents [A] (command 0 only).
Decoded decode_currents(std::span<const std::uint8_t> bytes, Vec3& amps);
/// Decodes a calibration command's counts a-f; false if the report is not one.
bool decode_calibrate(std::span<const std::uint8_t> bytes, std::array<std::int16_t, 6>& counts);

/// Forward kinematics: encoder counts (a, b, c) -> position, device frame [m] (non-finite
/// where polhem_v3's linkage cannot close).
Vec3 position_m(const std::array<std::int16_t, 6>& encoder, Config c);
/// Jacobian transpose: force [N] at the end effector -> motor currents [A] (no gravity
/// compensation: zero force is zero current).
Vec3 motor_currents_a(const Vec3& force_n, const std::array<std::int16_t, 6>& encoder, Config c);
/// The device side, for the emulator: the encoder counts (a, b, c; d-f 0) whose forward
/// kinematics give `p` [m, device] (Newton from the calibration pose; rounded to counts).
std::array<std::int16_t, 6> encoders_for(const Vec3& p, Config c);
/// The force [N, device] that motor currents `amps` [A] produce at `encoder` (the inverse
/// of motor_currents_a: its 3x3 map solved).
Vec3 force_from_currents(const Vec3& amps, const std::array<std::int16_t, 6>& encoder, Config c);
/// The farthest a calibrated unit's handle is from its workspace origin [m]: its calibration
/// pose (the farthest place upstream puts it) plus 5 cm.
double reach_m(Config c);
/// "" if `p` [m, device] (a calibrated unit's position under `c`) can be one, else why not:
/// no pose (the linkage cannot close) or beyond reach_m: the unit is of the other configuration.
std::string check_pose(const Vec3& p, Config c);
/// The capabilities under `c` (workspace: a cube of +-workspace_radius around its origin).
DeviceCaps caps(Config c);
}  // namespace polhem

}  // namespace isotouch::servo::hid
