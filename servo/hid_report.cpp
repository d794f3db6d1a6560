#include "isotouch/servo/hid_report.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace isotouch::servo::hid {
namespace {

// Little-endian writer / reader over a fixed buffer (bounds checked by the callers' sizes).
struct Writer {
  std::uint8_t* p;
  void u8(std::uint8_t v) { *p++ = v; }
  void u16(std::uint16_t v) { u8(std::uint8_t(v)), u8(std::uint8_t(v >> 8)); }
  void u32(std::uint32_t v) { u16(std::uint16_t(v)), u16(std::uint16_t(v >> 16)); }
  void i32(std::int32_t v) { u32(std::uint32_t(v)); }
};
struct Reader {
  const std::uint8_t* p;
  std::uint8_t u8() { return *p++; }
  std::uint16_t u16() {
    const std::uint16_t lo = u8();
    return std::uint16_t(lo | (std::uint16_t(u8()) << 8));
  }
  std::uint32_t u32() {
    const std::uint32_t lo = u16();
    return lo | (std::uint32_t(u16()) << 16);
  }
  std::int32_t i32() { return std::int32_t(u32()); }
};

/// `v / unit` rounded to int32; false if non-finite or out of the int32 range.
bool fixed(double v, double unit, std::int32_t& out) {
  const double q = std::round(v / unit);
  if (!(q >= -2147483647.0 && q <= 2147483647.0)) return false;
  out = std::int32_t(q);
  return true;
}
std::int32_t fixed_or_zero(double v, double unit) {
  std::int32_t q = 0;
  return fixed(v, unit, q) ? q : 0;
}
/// A non-negative limit in `unit` as uint32 (infinite or too large: UINT32_MAX = none).
std::uint32_t limit_u32(double v, double unit) {
  const double q = std::round(v / unit);
  return q >= 0 && q < 4294967295.0 ? std::uint32_t(q) : 0xFFFFFFFFu;
}
double limit_from(std::uint32_t q, double unit) { return q == 0xFFFFFFFFu ? INFINITY : double(q) * unit; }

/// Checks the size, ID, version and CRC of a v1 report; "" if good.
std::string check_frame(std::span<const std::uint8_t> b, std::uint8_t id, std::size_t size, const char* what) {
  if (b.size() != size)
    return std::string(what) + " report: " + std::to_string(b.size()) + " bytes, expected " + std::to_string(size);
  if (b[0] != id) return std::string(what) + " report: report ID " + std::to_string(b[0]) + ", expected " + std::to_string(id);
  if (b[1] != kVersion)
    return std::string(what) + " report: protocol version " + std::to_string(b[1]) + ", expected " + std::to_string(kVersion);
  const std::uint16_t want = crc16(b.first(size - 2));
  const std::uint16_t got = std::uint16_t(b[size - 2] | (b[size - 1] << 8));
  if (want != got) return std::string(what) + " report: CRC mismatch (garbled bytes)";
  return {};
}
template <std::size_t N>
void seal(std::array<std::uint8_t, N>& b) {
  const std::uint16_t c = crc16(std::span<const std::uint8_t>(b.data(), N - 2));
  b[N - 2] = std::uint8_t(c);
  b[N - 1] = std::uint8_t(c >> 8);
}
}  // namespace

std::uint16_t crc16(std::span<const std::uint8_t> bytes) {
  std::uint16_t c = 0xFFFF;
  for (std::uint8_t b : bytes) {
    c ^= std::uint16_t(b << 8);
    for (int i = 0; i < 8; ++i) c = (c & 0x8000) ? std::uint16_t((c << 1) ^ 0x1021) : std::uint16_t(c << 1);
  }
  return c;
}

std::array<std::uint8_t, kInputSize> encode(const InputReport& r) {
  std::array<std::uint8_t, kInputSize> b{};
  Writer w{b.data()};
  w.u8(kInputId), w.u8(kVersion), w.u16(r.flags), w.u32(r.sequence), w.u32(r.device_time_us);
  w.i32(fixed_or_zero(r.position_m.x, kPositionUnitM));
  w.i32(fixed_or_zero(r.position_m.y, kPositionUnitM));
  w.i32(fixed_or_zero(r.position_m.z, kPositionUnitM));
  w.u32(r.buttons);
  seal(b);
  return b;
}

Decoded decode(std::span<const std::uint8_t> b, InputReport& out) {
  if (std::string e = check_frame(b, kInputId, kInputSize, "input"); !e.empty()) return {e};
  Reader r{b.data() + 2};
  InputReport v;
  v.flags = r.u16();
  v.sequence = r.u32();
  v.device_time_us = r.u32();
  const std::int32_t x = r.i32(), y = r.i32(), z = r.i32();
  v.position_m = Vec3{x * kPositionUnitM, y * kPositionUnitM, z * kPositionUnitM};
  v.buttons = r.u32();
  if (r.u16() != 0) return {"input report: reserved bytes 28-29 are not zero"};
  out = v;
  return {};
}

std::array<std::uint8_t, kOutputSize> encode(const OutputReport& r) {
  std::array<std::uint8_t, kOutputSize> b{};
  std::int32_t f[3];
  const bool ok = fixed(r.force_n.x, kForceUnitN, f[0]) && fixed(r.force_n.y, kForceUnitN, f[1]) &&
                  fixed(r.force_n.z, kForceUnitN, f[2]);
  if (!ok) f[0] = f[1] = f[2] = 0;
  Writer w{b.data()};
  w.u8(kOutputId), w.u8(kVersion), w.u16(ok && r.enable ? 1 : 0), w.u32(r.sequence), w.u32(r.answers);
  w.i32(f[0]), w.i32(f[1]), w.i32(f[2]);
  seal(b);
  return b;
}

Decoded decode(std::span<const std::uint8_t> b, OutputReport& out) {
  if (std::string e = check_frame(b, kOutputId, kOutputSize, "output"); !e.empty()) return {e};
  Reader r{b.data() + 2};
  OutputReport v;
  const std::uint16_t flags = r.u16();
  if (flags > 1) return {"output report: unknown flags " + std::to_string(flags)};
  v.enable = flags & 1;
  v.sequence = r.u32();
  v.answers = r.u32();
  const std::int32_t x = r.i32(), y = r.i32(), z = r.i32();
  v.force_n = Vec3{x * kForceUnitN, y * kForceUnitN, z * kForceUnitN};
  if (r.u16() != 0) return {"output report: reserved bytes 24-25 are not zero"};
  out = v;
  return {};
}

std::array<std::uint8_t, kFeatureSize> encode_caps(const DeviceCaps& c) {
  std::array<std::uint8_t, kFeatureSize> b{};
  Writer w{b.data()};
  w.u8(kFeatureId), w.u8(kVersion), w.u8(std::uint8_t(std::clamp(c.dof, 0, 255))),
      w.u8(std::uint8_t(std::clamp(c.buttons, 0, 32)));
  w.u16(std::uint16_t(std::clamp(c.native_rate_hz, 0.0, 65535.0)));
  w.u16(std::uint16_t(std::clamp(std::round(c.watchdog_s * 1e3), 0.0, 65535.0)));
  for (const Vec3& v : {c.workspace_min_m, c.workspace_max_m}) {
    // An unbounded side is the int32 extreme.
    for (double x : {v.x, v.y, v.z})
      w.i32(std::isfinite(x) ? fixed_or_zero(x, kPositionUnitM) : (x < 0 ? INT32_MIN : INT32_MAX));
  }
  w.u32(limit_u32(c.max_force_n, kForceUnitN));
  w.u32(limit_u32(c.max_stiffness_n_per_m, 1.0));
  w.u32(limit_u32(c.max_damping_n_s_per_m, 1e-3));
  w.u32(limit_u32(c.position_resolution_m, 1e-9));
  const std::size_t n = std::min<std::size_t>(c.name.size(), 14);
  std::memcpy(w.p, c.name.data(), n);  // NUL-padded, bytes 48-61
  seal(b);
  return b;
}

Decoded decode_caps(std::span<const std::uint8_t> b, DeviceCaps& out) {
  if (std::string e = check_frame(b, kFeatureId, kFeatureSize, "feature"); !e.empty()) return {e};
  Reader r{b.data() + 2};
  DeviceCaps c;
  c.dof = r.u8();
  c.buttons = r.u8();
  c.native_rate_hz = r.u16();
  c.watchdog_s = r.u16() * 1e-3;
  double ws[6];
  for (double& x : ws) {
    const std::int32_t q = r.i32();
    x = q == INT32_MIN ? -INFINITY : q == INT32_MAX ? INFINITY : q * kPositionUnitM;
  }
  c.workspace_min_m = Vec3{ws[0], ws[1], ws[2]};
  c.workspace_max_m = Vec3{ws[3], ws[4], ws[5]};
  if (!(ws[0] < ws[3] && ws[1] < ws[4] && ws[2] < ws[5])) return {"feature report: empty workspace box"};
  c.max_force_n = limit_from(r.u32(), kForceUnitN);
  c.max_stiffness_n_per_m = limit_from(r.u32(), 1.0);
  c.max_damping_n_s_per_m = limit_from(r.u32(), 1e-3);
  c.position_resolution_m = limit_from(r.u32(), 1e-9);
  if (c.dof < 1 || c.dof > 6) return {"feature report: " + std::to_string(c.dof) + " degrees of freedom, expected 1 to 6"};
  if (c.buttons > 32) return {"feature report: " + std::to_string(c.buttons) + " buttons, at most 32"};
  if (!(c.max_force_n > 0)) return {"feature report: maximum force 0 N"};
  const char* name = reinterpret_cast<const char*>(r.p);
  c.name.assign(name, strnlen(name, 14));
  for (char ch : c.name)
    if (ch < 0x20 || ch > 0x7e) return {"feature report: the device name has a non-printable byte"};
  out = c;
  return {};
}

// ---------------------------------------------------------------------------------------
namespace polhem {
namespace {
// haptikfabrikenapi's Kinematics::configuration::polhem_v1 (lengths [m], counts per rev).
constexpr double kCapstan = 0.010, kBodyA = 0.180, kBodyBC = 0.100;
constexpr double kLn = 0.058, kLb = 0.174, kLc = 0.133;
constexpr double kOrigin[3] = {0.140, 0.0, 0.100};
constexpr double kCpr = 2000, kTorqueConstant = 0.0538;  // [N m / A]
constexpr double kDir = -1.0;  // motor_and_body_aligned a, b, c = true
constexpr double kPi = 3.14159265358979323846;

struct Angles {
  double a, b, c;  ///< body angles theta_A, theta_B, theta_C [rad]
};
Angles angles(double a, double b, double c) {
  auto body = [](double counts, double body_d) { return kDir * (2 * kPi * counts / kCpr) * kCapstan / body_d; };
  return {body(a, kBodyA), body(b, kBodyBC), body(c, kBodyBC)};
}
Angles angles(const std::array<std::int16_t, 6>& e) { return angles(e[0], e[1], e[2]); }
Vec3 position_of(const Angles& t) {
  const double r = kLb * std::sin(t.b) + kLc * std::sin(t.c);
  return Vec3{std::cos(t.a) * r - kOrigin[0], std::sin(t.a) * r - kOrigin[1],
              kLn + kLb * std::cos(t.b) - kLc * std::cos(t.c) - kOrigin[2]};
}
/// Solves the 3x3 system with columns `c0, c1, c2` for `rhs` (Cramer); false if singular.
bool solve3(const Vec3& c0, const Vec3& c1, const Vec3& c2, const Vec3& rhs, Vec3& x) {
  const double det = dot(c0, cross(c1, c2));
  if (!(std::abs(det) > 1e-18)) return false;
  x = Vec3{dot(rhs, cross(c1, c2)), dot(c0, cross(rhs, c2)), dot(c0, cross(c1, rhs))} / det;
  return true;
}
std::int16_t le16(std::span<const std::uint8_t> b, std::size_t i) { return std::int16_t(b[i] | (b[i + 1] << 8)); }
void put16(std::array<std::uint8_t, kReportSize>& b, std::size_t i, std::int16_t v) {
  b[i] = std::uint8_t(std::uint16_t(v));
  b[i + 1] = std::uint8_t(std::uint16_t(v) >> 8);
}
}  // namespace

Decoded decode(std::span<const std::uint8_t> b, Input& out) {
  if (b.size() != kReportSize)
    return {"Polhem input report: " + std::to_string(b.size()) + " bytes, expected " + std::to_string(kReportSize)};
  Input v;
  for (std::size_t i = 0; i < 6; ++i) v.encoder[i] = le16(b, 2 * i);
  v.info = le16(b, 12);
  if (v.info != 0 && v.info != 1) return {"Polhem input report: info " + std::to_string(v.info) + ", expected 0 or 1"};
  out = v;
  return {};
}

std::array<std::uint8_t, kReportSize> encode(const Input& in) {
  std::array<std::uint8_t, kReportSize> b{};
  for (std::size_t i = 0; i < 6; ++i) put16(b, 2 * i, in.encoder[i]);
  put16(b, 12, in.info);
  return b;
}

std::array<std::uint8_t, kReportSize> encode_currents(const Vec3& amps) {
  std::array<std::uint8_t, kReportSize> b{};
  const double a[3] = {amps.x, amps.y, amps.z};
  for (std::size_t i = 0; i < 3; ++i) {
    const double ma = std::isfinite(a[i]) ? std::clamp(a[i], -kMaxCurrentA, kMaxCurrentA) * 1e3 : 0.0;
    put16(b, 2 * i, std::int16_t(std::lround(ma)));
  }
  return b;  // command 0: currents
}

std::array<std::uint8_t, kReportSize> encode_calibrate() {
  std::array<std::uint8_t, kReportSize> b{};
  put16(b, 6, 1);       // command 1: set the encoder counters
  put16(b, 12, -5000);  // attr2: encoder c (calibrate_enc_c of polhem_v1); a, b, d-f: 0
  return b;
}

Decoded decode_currents(std::span<const std::uint8_t> b, Vec3& amps) {
  if (b.size() != kReportSize)
    return {"Polhem output report: " + std::to_string(b.size()) + " bytes, expected " + std::to_string(kReportSize)};
  if (le16(b, 6) != 0) return {"Polhem output report: command " + std::to_string(le16(b, 6)) + ", not currents"};
  amps = Vec3{le16(b, 0) * 1e-3, le16(b, 2) * 1e-3, le16(b, 4) * 1e-3};
  return {};
}

Vec3 position_m(const std::array<std::int16_t, 6>& e) { return position_of(angles(e)); }

std::array<std::int16_t, 6> encoders_for(const Vec3& p) {
  Vec3 q{0, 0, -5000};  // counts a, b, c: the calibration pose
  auto pos = [](const Vec3& c) { return position_of(angles(c.x, c.y, c.z)); };
  for (int i = 0; i < 100; ++i) {
    const Vec3 e = pos(q) - p, h{1, 0, 0}, k{0, 1, 0}, l{0, 0, 1};
    Vec3 step;
    if (norm(e) < 1e-9 || !solve3(pos(q + h) - pos(q - h), pos(q + k) - pos(q - k), pos(q + l) - pos(q - l), e * 2.0, step))
      break;
    const double big = norm(step);
    q -= big > 300 ? step * (300 / big) : step;  // damped: at most 300 counts a step
  }
  auto count = [](double v) { return std::int16_t(std::clamp(std::lround(v), -32768L, 32767L)); };
  return {count(q.x), count(q.y), count(q.z), 0, 0, 0};
}

Vec3 force_from_currents(const Vec3& amps, const std::array<std::int16_t, 6>& e) {
  Vec3 f;
  if (!solve3(motor_currents_a({1, 0, 0}, e), motor_currents_a({0, 1, 0}, e), motor_currents_a({0, 0, 1}, e), amps, f))
    return {};
  return f;
}

Vec3 motor_currents_a(const Vec3& f, const std::array<std::int16_t, 6>& e) {
  const Angles t = angles(e);
  const double r = kLb * std::sin(t.b) + kLc * std::sin(t.c);
  // Joint torques tau = J^T F (the gravity constant of polhem_v1 is 0).
  const double ta = -std::sin(t.a) * r * f.x + std::cos(t.a) * r * f.y;
  const double tb = kLb * std::cos(t.a) * std::cos(t.b) * f.x + kLb * std::sin(t.a) * std::cos(t.b) * f.y -
                    kLb * std::sin(t.b) * f.z;
  const double tc = kLc * std::cos(t.a) * std::cos(t.c) * f.x + kLc * std::sin(t.a) * std::cos(t.c) * f.y +
                    kLc * std::sin(t.c) * f.z;
  // Body torque -> motor torque through the capstan ratio -> current.
  return Vec3{ta * kDir * kCapstan / kBodyA, tb * kDir * kCapstan / kBodyBC, tc * kDir * kCapstan / kBodyBC} /
         kTorqueConstant;
}

DeviceCaps caps() {
  DeviceCaps c;
  c.name = "Polhem v1";
  c.dof = 3;
  c.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
  c.workspace_max_m = Vec3{0.1, 0.1, 0.1};
  c.max_force_n = 5.0;               // max_linear_force
  c.max_stiffness_n_per_m = 800.0;   // max_linear_stiffness
  c.max_damping_n_s_per_m = 8.0;     // max_linear_damping
  c.native_rate_hz = 1000;
  c.buttons = 1;
  c.position_resolution_m = kLb * 2 * kPi / kCpr * kCapstan / kBodyBC;  // one count of encoder b at the tip
  c.watchdog_s = 0.5;
  // Lock-step: the firmware answers one report per command, so the newest pose is one USB
  // round trip old (1-2 ms at full speed, more when the host is busy); the servo's default of
  // two periods would call a healthy Polhem stale. 8 ms is four round trips, under the
  // firmware's own 0.5 s watchdog by far.
  c.stale_timeout_s = 0.008;
  return c;
}
}  // namespace polhem

}  // namespace isotouch::servo::hid
