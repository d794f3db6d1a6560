#include "isotouch/servo/hid_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
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
/// A force component in `unit`, rounded toward zero: the device never gets more than was
/// asked (rounded to nearest, each component could add half a unit: |F| past the limit).
bool fixed_force(double v, double unit, std::int32_t& out) {
  const double q = std::trunc(v / unit);
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
  const bool ok = fixed_force(r.force_n.x, kForceUnitN, f[0]) && fixed_force(r.force_n.y, kForceUnitN, f[1]) &&
                  fixed_force(r.force_n.z, kForceUnitN, f[2]);
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
const char* const kConfigSource =
    "forsslund/hfabapi @aadabaa82ce9 (2023-04-05): hfab_math.h Kinematics::configuration::polhem_v1/polhem_v3, "
    "hfab_kinematics.cpp calculate_pose/computePosition/computeMotorAmps, hfab_polhem.h polhemKinematics";

namespace {
constexpr double kPi = 3.14159265358979323846;

/// One of haptikfabriken's Kinematics::configuration, the fields the maths use.
struct Params {
  double capstan[3], body[3];  ///< diameter_capstan_a-c, diameter_body_a-c [m]
  double length[3];            ///< length_body_a-c [m] (the serial chain; polhem_v3 uses its linkage's)
  double origin[3];            ///< workspace_origin_x-z [m]
  double radius;               ///< workspace_radius [m]
  double torque_constant[3];   ///< torque_constant_motor_a-c [N m / A]
  double cpr[3];               ///< cpr_encoder_a-c [counts per motor turn]
  double max_force, max_stiffness, max_damping;  ///< [N], [N/m], [N s/m]
  std::int16_t calibrate[6];   ///< calibrate_enc_a-f [counts]
  bool aligned[3];             ///< motor_and_body_aligned_a-c
};
// hfab_math.h: polhem_v1() (variant 2) and polhem_v3() (variant 3, "2020-12-21").
constexpr Params kV1{{0.010, 0.010, 0.010}, {0.180, 0.100, 0.100}, {0.058, 0.174, 0.133}, {0.140, 0.0, 0.100},
                     0.100, {0.0538, 0.0538, 0.0538}, {2000, 2000, 2000}, 5.0, 800.0, 8.0,
                     {0, 0, -5000, 0, 0, 0}, {true, true, true}};
constexpr Params kV3{{0.0288534, 0.0136981, 0.0137281}, {0.175, 0.100, 0.100}, {0.1, 0.165, 0.1308},
                     {0.2045, 0.0, 0.0325}, 0.150, {0.0603, 0.0538, 0.0538}, {4096, 4096, 4096}, 5.0, 2000.0, 1.0,
                     {8312, -10366, 19764, 0, 30, 0}, {false, true, false}};
const Params& params(Config c) { return c == Config::kV3 ? kV3 : kV1; }

// hfab_polhem.h: the Polhem's five-bar linkage [m].
constexpr double kL0 = 34e-3, kL1 = 165e-3, kL2 = 25e-3, kL3 = 190e-3, kL4 = 34e-3, kL5 = 130.8e-3;

struct Angles {
  double a, b, c;  ///< body angles theta_A, theta_B, theta_C [rad]
};
/// calculate_pose: motor angle through the capstan ratio, the motor's direction by
/// motor_and_body_aligned (aligned: -1).
Angles angles(const Params& k, double a, double b, double c) {
  auto body = [&](int i, double counts) {
    return (k.aligned[i] ? -1.0 : 1.0) * (2 * kPi * counts / k.cpr[i]) * k.capstan[i] / k.body[i];
  };
  return {body(0, a), body(1, b), body(2, c)};
}
/// polhemKinematics: the handle of the linkage driven by theta_B and theta_C, turned by
/// theta_A (NaN where the linkage cannot close).
Vec3 linkage(const Angles& t) {
  const double l1c = kL1 * std::cos(t.b), l1s = kL1 * std::sin(t.b);
  const double a = kL0 + l1c;
  const double sq1 = (a - kL2 * std::cos(t.c)) * (a - kL2 * std::cos(t.c));
  const double sq2 = (l1s - kL2 * std::sin(t.c)) * (l1s - kL2 * std::sin(t.c));
  const double sq3 = a * a, sq4 = l1s * l1s;
  const double r1 = std::sqrt(sq1 + sq2), r2 = std::sqrt(sq3 + sq4);
  const double x1 = 2 * r2 * r1, x2 = -kL3 * kL3 + kL4 * kL4 + sq1 + sq2, x3 = 2 * kL1 * r2, x4 = 2 * kL4 * r1;
  const double x5 = -kL0 * kL0 + kL1 * kL1 + sq3 + sq4, x6 = -kL2 * kL2 + sq1 + sq2 + sq3 + sq4;
  const double lambda = t.b - std::acos(x5 / x3) - std::acos(x2 / x4) - std::acos(x6 / x1);
  const double reach = kL0 / 2 + l1c + kL5 * std::cos(lambda);
  return Vec3{reach * std::cos(t.a), reach * std::sin(t.a), l1s + kL5 * std::sin(lambda)};
}
/// computePosition: the serial chain (polhem_v1) or the linkage (polhem_v3), less the origin.
Vec3 position_of(Config c, const Angles& t) {
  const Params& k = params(c);
  const Vec3 origin{k.origin[0], k.origin[1], k.origin[2]};
  if (c == Config::kV3) return linkage(t) - origin;
  const double r = k.length[1] * std::sin(t.b) + k.length[2] * std::sin(t.c);
  return Vec3{std::cos(t.a) * r, std::sin(t.a) * r, k.length[0] + k.length[1] * std::cos(t.b) - k.length[2] * std::cos(t.c)} -
         origin;
}
Vec3 position_of(Config c, const Vec3& counts) { return position_of(c, angles(params(c), counts.x, counts.y, counts.z)); }
/// Joint torques tau = J^T F: the chain's analytic Jacobian (polhem_v1, gravity constant 0),
/// or polhemComputeMotorAmps' central differences of the linkage (step 1e-5 rad; its
/// gravity compensation left out).
Vec3 joint_torques(Config c, const Angles& t, const Vec3& f) {
  if (c == Config::kV3) {
    constexpr double h = 1e-5;
    auto column = [&](Angles p, Angles m) { return (linkage(p) - linkage(m)) / h; };
    const Vec3 ja = column({t.a + h / 2, t.b, t.c}, {t.a - h / 2, t.b, t.c});
    const Vec3 jb = column({t.a, t.b + h / 2, t.c}, {t.a, t.b - h / 2, t.c});
    const Vec3 jc = column({t.a, t.b, t.c + h / 2}, {t.a, t.b, t.c - h / 2});
    return Vec3{dot(ja, f), dot(jb, f), dot(jc, f)};
  }
  const Params& k = kV1;
  const double lb = k.length[1], lc = k.length[2];
  const double r = lb * std::sin(t.b) + lc * std::sin(t.c);
  return Vec3{-std::sin(t.a) * r * f.x + std::cos(t.a) * r * f.y,
              lb * std::cos(t.a) * std::cos(t.b) * f.x + lb * std::sin(t.a) * std::cos(t.b) * f.y - lb * std::sin(t.b) * f.z,
              lc * std::cos(t.a) * std::cos(t.c) * f.x + lc * std::sin(t.a) * std::cos(t.c) * f.y + lc * std::sin(t.c) * f.z};
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
std::string mm3(const Vec3& p) {
  char s[96];
  std::snprintf(s, sizeof s, "(%.1f, %.1f, %.1f) mm", p.x * 1e3, p.y * 1e3, p.z * 1e3);
  return s;
}
}  // namespace

const char* config_name(Config c) { return c == Config::kV3 ? "polhem_v3" : "polhem_v1"; }

bool parse_config(const std::string& s, Config& c) {
  if (s == "v1" || s == "polhem_v1") return c = Config::kV1, true;
  if (s == "v3" || s == "polhem_v3") return c = Config::kV3, true;
  return false;
}

std::array<std::int16_t, 6> calibration_counts(Config c) {
  const Params& k = params(c);
  return {k.calibrate[0], k.calibrate[1], k.calibrate[2], k.calibrate[3], k.calibrate[4], k.calibrate[5]};
}

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

Vec3 limit_currents_a(const Vec3& amps, double cap) {
  double a[3] = {amps.x, amps.y, amps.z};
  // One non-finite current makes the whole vector meaningless: zeroing only that motor would
  // push the other two in a direction nobody asked for.
  if (!std::isfinite(a[0]) || !std::isfinite(a[1]) || !std::isfinite(a[2])) return {};
  std::size_t big = 0;  // the motor with the largest |current|
  for (std::size_t i = 1; i < 3; ++i)
    if (std::abs(a[i]) > std::abs(a[big])) big = i;
  if (!(std::abs(a[big]) > cap)) return amps;
  // min over i of cap / |a_i| is the largest one's: all three scaled by it (the force keeps
  // its direction, smaller), and the largest set to the cap itself (x * (cap / x) can be an
  // ulp off it).
  const double s = cap / std::abs(a[big]);
  for (double& v : a) v *= s;
  a[big] = std::copysign(cap, a[big]);
  return Vec3{a[0], a[1], a[2]};
}

std::array<std::uint8_t, kReportSize> encode_currents(const Vec3& amps) {
  std::array<std::uint8_t, kReportSize> b{};
  const Vec3 lim = limit_currents_a(amps);
  const double a[3] = {lim.x, lim.y, lim.z};
  for (std::size_t i = 0; i < 3; ++i) put16(b, 2 * i, std::int16_t(std::lround(a[i] * 1e3)));  // |a_i| <= 2 A: fits
  return b;  // command 0: currents
}

std::array<std::uint8_t, kReportSize> encode_calibrate(Config c) {
  const auto counts = calibration_counts(c);
  std::array<std::uint8_t, kReportSize> b{};
  for (std::size_t i = 0; i < 3; ++i) {
    put16(b, 8 + 2 * i, counts[i]);  // attr 0-2: encoders a-c
    put16(b, 2 * i, counts[3 + i]);  // the current fields: encoders d-f
  }
  put16(b, 6, 1);  // command 1: set the encoder counters
  return b;
}

Decoded decode_currents(std::span<const std::uint8_t> b, Vec3& amps) {
  if (b.size() != kReportSize)
    return {"Polhem output report: " + std::to_string(b.size()) + " bytes, expected " + std::to_string(kReportSize)};
  if (le16(b, 6) != 0) return {"Polhem output report: command " + std::to_string(le16(b, 6)) + ", not currents"};
  amps = Vec3{le16(b, 0) * 1e-3, le16(b, 2) * 1e-3, le16(b, 4) * 1e-3};
  return {};
}

bool decode_calibrate(std::span<const std::uint8_t> b, std::array<std::int16_t, 6>& counts) {
  if (b.size() != kReportSize || le16(b, 6) != 1) return false;
  for (std::size_t i = 0; i < 3; ++i) counts[i] = le16(b, 8 + 2 * i), counts[3 + i] = le16(b, 2 * i);
  return true;
}

Vec3 position_m(const std::array<std::int16_t, 6>& e, Config c) { return position_of(c, Vec3{double(e[0]), double(e[1]), double(e[2])}); }

std::array<std::int16_t, 6> encoders_for(const Vec3& p, Config c) {
  const auto home = calibration_counts(c);
  Vec3 q{double(home[0]), double(home[1]), double(home[2])};
  auto pos = [c](const Vec3& counts) { return position_of(c, counts); };
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

Vec3 force_from_currents(const Vec3& amps, const std::array<std::int16_t, 6>& e, Config c) {
  Vec3 f;
  if (!solve3(motor_currents_a({1, 0, 0}, e, c), motor_currents_a({0, 1, 0}, e, c), motor_currents_a({0, 0, 1}, e, c),
              amps, f))
    return {};
  return f;
}

Vec3 motor_currents_a(const Vec3& f, const std::array<std::int16_t, 6>& e, Config c) {
  const Params& k = params(c);
  const Vec3 tau = joint_torques(c, angles(k, e[0], e[1], e[2]), f);
  // Body torque -> motor torque through the capstan ratio and the motor's direction -> current.
  auto amps = [&](int i, double t) {
    return t * (k.aligned[i] ? -1.0 : 1.0) * k.capstan[i] / k.body[i] / k.torque_constant[i];
  };
  return Vec3{amps(0, tau.x), amps(1, tau.y), amps(2, tau.z)};
}

double reach_m(Config c) { return norm(position_m(calibration_counts(c), c)) + 0.05; }

std::string check_pose(const Vec3& p, Config c) {
  const Config other = c == Config::kV3 ? Config::kV1 : Config::kV3;
  const std::string is_it = std::string(": the unit is not a ") + config_name(c) + " (a " + config_name(other) +
                            "? --haptic polhem:...,config=" + (other == Config::kV3 ? "v3" : "v1") + ")";
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
    return std::string("Polhem: its encoder counts give no pose under ") + config_name(c) +
           " (the linkage cannot close there)" + is_it;
  if (norm(p) > reach_m(c)) {
    char d[64];
    std::snprintf(d, sizeof d, "%.0f mm from its workspace origin, beyond its reach (%.0f mm)", norm(p) * 1e3,
                  reach_m(c) * 1e3);
    return std::string("Polhem: position ") + mm3(p) + " under " + config_name(c) + " is " + d + is_it;
  }
  return {};
}

DeviceCaps caps(Config c) {
  const Params& k = params(c);
  DeviceCaps d;
  d.name = c == Config::kV3 ? "Polhem v3" : "Polhem v1";
  d.dof = 3;
  d.workspace_min_m = Vec3{-k.radius, -k.radius, -k.radius};
  d.workspace_max_m = Vec3{k.radius, k.radius, k.radius};
  d.max_force_n = k.max_force;           // max_linear_force
  d.max_stiffness_n_per_m = k.max_stiffness;  // max_linear_stiffness
  d.max_damping_n_s_per_m = k.max_damping;    // max_linear_damping
  d.native_rate_hz = 1000;
  d.buttons = 1;
  // The tip's largest move for one count of any motor, at the workspace centre.
  const auto e = encoders_for(Vec3{}, c);
  double step = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    auto ep = e, em = e;
    ++ep[i], --em[i];
    step = std::max(step, norm(position_m(ep, c) - position_m(em, c)) / 2);
  }
  d.position_resolution_m = step;
  d.watchdog_s = 0.5;
  // Lock-step: the firmware answers one report per command, so the newest pose is one USB
  // round trip old (1-2 ms at full speed, more when the host is busy); the servo's default of
  // two periods would call a healthy Polhem stale. 8 ms is four round trips, under the
  // firmware's own 0.5 s watchdog by far.
  d.stale_timeout_s = 0.008;
  return d;
}
}  // namespace polhem

}  // namespace isotouch::servo::hid
