// The report codecs: protocol v1 round trips (input, output, capabilities), every malformed
// report refused with its reason, forces that cannot be encoded sent as a disabled zero; the
// Polhem's 14-byte reports and kinematics (position, Jacobian transpose by virtual work).
#include <gtest/gtest.h>

#include <cstdio>

#include <algorithm>
#include <cmath>
#include <vector>

#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/hid_report.h"
#include "isotouch/servo/report_device.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::servo::hid;

TEST(HidReport, InputRoundTripsAtMicrometreResolution) {
  InputReport in;
  in.flags = kForceEnabled | kWatchdog;
  in.sequence = 0xFFFFFFF0u;
  in.device_time_us = 123456789u;
  in.position_m = Vec3{0.0123456, -0.0999999, 0.05};
  in.buttons = 0x5;
  const auto b = encode(in);
  ASSERT_EQ(b.size(), kInputSize);
  EXPECT_EQ(b[0], kInputId);
  InputReport out;
  ASSERT_TRUE(decode(b, out)) << decode(b, out).error;
  EXPECT_EQ(out.flags, in.flags);
  EXPECT_EQ(out.sequence, in.sequence);
  EXPECT_EQ(out.device_time_us, in.device_time_us);
  EXPECT_EQ(out.buttons, in.buttons);
  EXPECT_NEAR(out.position_m.x, in.position_m.x, 0.5e-6);
  EXPECT_NEAR(out.position_m.y, in.position_m.y, 0.5e-6);
  EXPECT_NEAR(out.position_m.z, in.position_m.z, 0.5e-6);
}

TEST(HidReport, OutputRoundTripsAndNonFiniteForceIsADisabledZero) {
  OutputReport o;
  o.enable = true, o.sequence = 7, o.answers = 41, o.force_n = Vec3{1.234, -3.3, 0.0004};
  OutputReport back;
  ASSERT_TRUE(decode(encode(o), back));
  EXPECT_TRUE(back.enable);
  EXPECT_EQ(back.sequence, 7u);
  EXPECT_EQ(back.answers, 41u);
  EXPECT_NEAR(back.force_n.x, 1.234, 1e-3);  // rounded toward zero: within one unit
  EXPECT_NEAR(back.force_n.y, -3.3, 1e-3);
  EXPECT_EQ(back.force_n.z, 0.0);
  for (double bad : {double(NAN), double(INFINITY), 1e12}) {
    o.force_n = Vec3{1, bad, 1};
    ASSERT_TRUE(decode(encode(o), back));
    EXPECT_FALSE(back.enable) << bad;
    EXPECT_EQ(back.force_n.x, 0.0);
    EXPECT_EQ(back.force_n.y, 0.0);
  }
}

// A force at the limit in any direction reaches the device no larger than it was (each
// component rounded toward zero; rounded to nearest, |F| could pass the limit by 0.87 mN).
TEST(HidReport, AnEncodedForceIsNeverLargerThanTheForceAsked) {
  OutputReport o, back;
  o.enable = true;
  double worst = 0;
  for (int i = 0; i < 2000; ++i) {
    const double th = 0.0137 * i, ph = 0.731 * i;
    const Vec3 u{std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)};
    o.force_n = u * 3.3;
    ASSERT_TRUE(decode(encode(o), back));
    worst = std::max(worst, norm(back.force_n) - norm(o.force_n));
    EXPECT_LE(norm(back.force_n), norm(o.force_n)) << "direction " << i;
    EXPECT_LT(norm(back.force_n - o.force_n), 1.8e-3) << "direction " << i;  // within one unit per axis
  }
  std::printf("largest |F| received - |F| asked: %.3g N\n", worst);
}

TEST(HidReport, CapabilitiesRoundTrip) {
  DeviceCaps c;
  c.name = "a-very-long-device-name";
  c.dof = 3, c.buttons = 2, c.native_rate_hz = 4000, c.watchdog_s = 0.05;
  c.workspace_min_m = Vec3{-0.1, -0.08, -0.05};
  c.workspace_max_m = Vec3{0.1, 0.08, 0.12};
  c.max_force_n = 8.5, c.max_stiffness_n_per_m = 2500, c.max_damping_n_s_per_m = 12.5;
  c.position_resolution_m = 2.5e-6;
  DeviceCaps d;
  ASSERT_TRUE(decode_caps(encode_caps(c), d));
  EXPECT_EQ(d.name, "a-very-long-de");  // 14 bytes
  EXPECT_EQ(d.dof, 3);
  EXPECT_EQ(d.buttons, 2);
  EXPECT_EQ(d.native_rate_hz, 4000);
  EXPECT_DOUBLE_EQ(d.watchdog_s, 0.05);
  EXPECT_NEAR(d.workspace_min_m.y, -0.08, 1e-9);
  EXPECT_NEAR(d.workspace_max_m.z, 0.12, 1e-9);
  EXPECT_DOUBLE_EQ(d.max_force_n, 8.5);
  EXPECT_DOUBLE_EQ(d.max_stiffness_n_per_m, 2500);
  EXPECT_DOUBLE_EQ(d.max_damping_n_s_per_m, 12.5);
  EXPECT_NEAR(d.position_resolution_m, 2.5e-6, 1e-15);
  // Unbounded limits stay unbounded.
  DeviceCaps inf;
  inf.max_force_n = 5;
  ASSERT_TRUE(decode_caps(encode_caps(inf), d));
  EXPECT_TRUE(std::isinf(d.max_stiffness_n_per_m));
  EXPECT_TRUE(std::isinf(d.workspace_max_m.x));
}

TEST(HidReport, MalformedReportsAreRefusedWithTheirReason) {
  InputReport in;
  in.position_m = Vec3{0.01, 0.02, 0.03};
  const auto good = encode(in);
  InputReport out;
  auto why = [&](std::vector<std::uint8_t> b) { return decode(b, out).error; };
  std::vector<std::uint8_t> b(good.begin(), good.end());
  EXPECT_NE(why({b.begin(), b.end() - 1}).find("31 bytes, expected 32"), std::string::npos);
  EXPECT_NE(why({}).find("0 bytes"), std::string::npos);
  auto id = b;
  id[0] = 9;
  EXPECT_NE(why(id).find("report ID 9"), std::string::npos);
  auto ver = b;
  ver[1] = 2;
  EXPECT_NE(why(ver).find("protocol version 2"), std::string::npos);
  for (std::size_t i = 2; i < b.size(); ++i) {  // any flipped bit: the CRC catches it
    auto flip = b;
    flip[i] ^= 0x10;
    EXPECT_NE(why(flip).find("CRC"), std::string::npos) << "byte " << i;
  }
  OutputReport o;
  EXPECT_FALSE(decode(std::vector<std::uint8_t>(good.begin(), good.end()), o));  // an input is not an output
  DeviceCaps caps;
  caps.max_force_n = 0;
  DeviceCaps back;
  EXPECT_NE(decode_caps(encode_caps(caps), back).error.find("maximum force 0 N"), std::string::npos);
}

TEST(HidReport, V1ProtocolMapsFlagsToStatus) {
  V1Protocol p;
  InputReport in;
  DeviceReading r;
  in.flags = kForceEnabled;
  ASSERT_EQ(p.decode_input(encode(in), r), "");
  EXPECT_EQ(r.status, DeviceStatus::kOk);
  in.flags = kFault;
  ASSERT_EQ(p.decode_input(encode(in), r), "");
  EXPECT_EQ(r.status, DeviceStatus::kFault);
  in.flags = kNotHomed;
  ASSERT_EQ(p.decode_input(encode(in), r), "");
  EXPECT_EQ(r.status, DeviceStatus::kFault);
  std::array<std::uint8_t, 64> buf{};
  const std::size_t n = p.encode_output(Vec3{1, 2, 3}, true, 99, buf);
  OutputReport o;
  ASSERT_TRUE(decode(std::span(buf.data(), n), o));
  EXPECT_EQ(o.answers, 99u);
  EXPECT_EQ(o.sequence, 1u);
  EXPECT_NEAR(o.force_n.z, 3.0, 1e-9);
}

namespace {
constexpr polhem::Config kConfigs[] = {polhem::Config::kV1, polhem::Config::kV3};
}  // namespace

TEST(Polhem, ReportsRoundTripAndCurrentsAreCapped) {
  polhem::Input in;
  in.encoder = {100, -200, 300, 5001, -5, 6};
  in.info = 1;
  polhem::Input out;
  ASSERT_TRUE(polhem::decode(polhem::encode(in), out));
  EXPECT_EQ(out.encoder, in.encoder);
  EXPECT_EQ(out.info, 1);
  auto bad = polhem::encode(in);
  bad[12] = 7;
  EXPECT_NE(polhem::decode(bad, out).error.find("info 7"), std::string::npos);
  EXPECT_FALSE(polhem::decode(std::vector<std::uint8_t>(15, 0), out));
  Vec3 amps;
  ASSERT_TRUE(polhem::decode_currents(polhem::encode_currents(Vec3{0.5, -9, 0.25}), amps));
  EXPECT_DOUBLE_EQ(amps.x, 0.111);                  // 0.5 * 2 / 9, to the mA: the vector scaled
  EXPECT_DOUBLE_EQ(amps.y, -polhem::kMaxCurrentA);  // capped
  EXPECT_DOUBLE_EQ(amps.z, 0.056);                  // 0.25 * 2 / 9
  ASSERT_TRUE(polhem::decode_currents(polhem::encode_currents(Vec3{0.5, -1, NAN}), amps));
  EXPECT_EQ(norm(amps), 0.0);                       // non-finite: no current on any motor
  EXPECT_FALSE(polhem::decode_currents(polhem::encode_calibrate(polhem::Config::kV1), amps));  // a command
}

// The calibration command as upstream's USB thread fills pc_to_hid_message (int16 LE after
// no report ID: currents a-c = calibrate_enc_d-f, command 1, attr 0-2 = calibrate_enc_a-c),
// with hfab_math.h's counts written out here.
TEST(Polhem, CalibrationCommandCarriesTheConfigurationsCounts) {
  auto le = [](const std::array<std::uint8_t, 14>& b, int i) { return std::int16_t(b[2 * i] | (b[2 * i + 1] << 8)); };
  const auto v1 = polhem::encode_calibrate(polhem::Config::kV1);
  EXPECT_EQ((std::array<int, 7>{le(v1, 0), le(v1, 1), le(v1, 2), le(v1, 3), le(v1, 4), le(v1, 5), le(v1, 6)}),
            (std::array<int, 7>{0, 0, 0, 1, 0, 0, -5000}));
  const auto v3 = polhem::encode_calibrate(polhem::Config::kV3);
  EXPECT_EQ((std::array<int, 7>{le(v3, 0), le(v3, 1), le(v3, 2), le(v3, 3), le(v3, 4), le(v3, 5), le(v3, 6)}),
            (std::array<int, 7>{0, 30, 0, 1, 8312, -10366, 19764}));
  std::array<std::int16_t, 6> counts{};
  ASSERT_TRUE(polhem::decode_calibrate(v3, counts));
  EXPECT_EQ(counts, polhem::calibration_counts(polhem::Config::kV3));
  EXPECT_FALSE(polhem::decode_calibrate(polhem::encode_currents(Vec3{}), counts));
}

TEST(Polhem, JacobianTransposeMatchesVirtualWork) {
  // tau . dq = F . dx: the currents times the torque constant, mapped back through the
  // capstan ratios, are the work per count of each motor. Torque constants and counts per
  // turn as hfab_math.h gives them.
  const Vec3 f{1.0, -0.5, 2.0};
  for (const polhem::Config c : kConfigs) {
    const bool v3 = c == polhem::Config::kV3;
    const auto e = v3 ? polhem::encoders_for(Vec3{0.01, -0.02, 0.015}, c) : std::array<std::int16_t, 6>{150, -400, 900, 0, 0, 0};
    const Vec3 amps = polhem::motor_currents_a(f, e, c);
    const double kt[3] = {v3 ? 0.0603 : 0.0538, 0.0538, 0.0538};  // [N m / A]
    const double step = 2 * M_PI / (v3 ? 4096 : 2000);               // motor radians per count
    for (int j = 0; j < 3; ++j) {
      auto ep = e, em = e;
      ep[std::size_t(j)] += 1, em[std::size_t(j)] -= 1;
      const Vec3 dx = (polhem::position_m(ep, c) - polhem::position_m(em, c)) / 2.0;  // per count
      const double work = dot(f, dx);
      const double a = j == 0 ? amps.x : j == 1 ? amps.y : amps.z;
      EXPECT_NEAR(a * kt[j] * step, work, 1e-3 * std::abs(work) + 1e-9) << polhem::config_name(c) << " motor " << j;
    }
  }
}

// polhem_v3's position is hfab_polhem.h's closed form of the five-bar linkage: checked here
// against the linkage itself. Motor b turns the arm L1 about (L0/2, 0), motor c the crank L2
// about (-L0/2, 0); the coupler L3 joins the crank's end to a point L4 back along the handle
// link from the arm's end, and the handle is L5 forward along it; all turned by theta_A.
TEST(Polhem, V3PositionClosesTheFiveBarLinkage) {
  constexpr double L0 = 0.034, L1 = 0.165, L2 = 0.025, L3 = 0.190, L4 = 0.034, L5 = 0.1308;
  const double origin[3] = {0.2045, 0.0, 0.0325};
  for (const Vec3 p : {Vec3{0, 0, 0}, Vec3{0.04, -0.03, 0.02}, Vec3{-0.05, 0.05, -0.04}}) {
    const auto e = polhem::encoders_for(p, polhem::Config::kV3);
    const Vec3 h = polhem::position_m(e, polhem::Config::kV3);
    // Body angles from the counts: capstan ratios and directions of hfab_math.h's polhem_v3.
    const double ta = 2 * M_PI * e[0] / 4096 * 0.0288534 / 0.175;
    const double tb = -2 * M_PI * e[1] / 4096 * 0.0136981 / 0.100;
    const double tc = 2 * M_PI * e[2] / 4096 * 0.0137281 / 0.100;
    const double hx = h.x + origin[0], hy = h.y + origin[1], hz = h.z + origin[2];
    EXPECT_NEAR(std::atan2(hy, hx), ta, 1e-9);
    const double r = std::hypot(hx, hy);  // the handle in the linkage's plane: (r, z)
    const double bx = L0 / 2 + L1 * std::cos(tb), bz = L1 * std::sin(tb);
    const double lambda = std::atan2(hz - bz, r - bx);
    EXPECT_NEAR(std::hypot(r - bx, hz - bz), L5, 1e-9);
    const double dx = bx - L4 * std::cos(lambda), dz = bz - L4 * std::sin(lambda);
    const double cx = -L0 / 2 + L2 * std::cos(tc), cz = L2 * std::sin(tc);
    EXPECT_NEAR(std::hypot(dx - cx, dz - cz), L3, 1e-9) << p.x << " " << p.y << " " << p.z;
  }
}

TEST(Polhem, ProtocolResendsCalibrationUntilTheDeviceStopsAskingAndPrependsReportIdZero) {
  PolhemProtocol p(polhem::Config::kV1);
  polhem::Input in;
  in.encoder = {10, 20, 30, 6000, 0, 0};
  in.info = 1;
  DeviceReading r;
  ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
  EXPECT_EQ(r.buttons, 1u);  // encoder d above 5000
  std::array<std::uint8_t, 64> buf{};
  ASSERT_EQ(p.pending_command(buf), 15u);
  EXPECT_EQ(buf[0], 0);
  EXPECT_EQ(buf[1 + 6], 1);  // command 1
  EXPECT_EQ(p.pending_command(buf), 0u);  // once per report that asks
  // The command was lost (the firmware keeps only its last queued report): it asks again.
  ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
  ASSERT_EQ(p.pending_command(buf), 15u);
  EXPECT_EQ(buf[1 + 6], 1);
  in.info = 0;  // calibrated: it stops asking
  ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
  EXPECT_EQ(p.pending_command(buf), 0u);
  EXPECT_EQ(r.status, DeviceStatus::kOk);
  ASSERT_EQ(p.encode_output(Vec3{0, 0, 1}, true, 0, buf), 15u);
  EXPECT_EQ(buf[0], 0);
  Vec3 amps;
  ASSERT_TRUE(polhem::decode_currents(std::span(buf.data() + 1, 14), amps));
  EXPECT_GT(norm(amps), 0.0);
  ASSERT_EQ(p.encode_output(Vec3{0, 0, 1}, false, 0, buf), 15u);  // disabled: no current
  ASSERT_TRUE(polhem::decode_currents(std::span(buf.data() + 1, 14), amps));
  EXPECT_EQ(norm(amps), 0.0);
}

namespace {
// Counts a calibrated unit of `unit` reports at `p`, as a host of `host` calibrated it:
// its own motion from its calibration pose, added to the host's calibration counts.
std::array<std::int16_t, 6> counts_seen(polhem::Config unit, polhem::Config host, const Vec3& p) {
  const auto here = polhem::encoders_for(p, unit), home = polhem::calibration_counts(unit);
  auto e = polhem::calibration_counts(host);
  for (std::size_t i = 0; i < 3; ++i) e[i] = std::int16_t(e[i] + here[i] - home[i]);
  return e;
}
}  // namespace

namespace {
// Calibrates `p` as a unit would be: it asks (info 1) and the protocol answers with the
// calibration command; the unit's next report (info 0) acknowledges it.
void command_calibration(PolhemProtocol& p) {
  polhem::Input in;
  in.info = 1;
  DeviceReading r;
  ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
  std::array<std::uint8_t, 64> buf{};
  ASSERT_EQ(p.pending_command(buf), 15u);
}
}  // namespace

TEST(Polhem, ProtocolFaultsAUnitOfTheOtherConfigurationAndSendsNoCurrent) {
  const Vec3 poses[] = {Vec3{0, 0, 0}, Vec3{0.05, 0, 0}, Vec3{-0.05, 0.05, 0.05}, Vec3{0.05, -0.05, -0.05}};
  for (const polhem::Config host : kConfigs) {
    const polhem::Config unit = host == polhem::Config::kV3 ? polhem::Config::kV1 : polhem::Config::kV3;
    // Its own configuration: every pose (and the calibration pose itself) is fine.
    for (const Vec3& q : poses) EXPECT_EQ(polhem::check_pose(polhem::position_m(polhem::encoders_for(q, host), host), host), "");
    EXPECT_EQ(polhem::check_pose(polhem::position_m(polhem::calibration_counts(host), host), host), "");
    int caught = 0;
    for (const Vec3& q : poses) {
      PolhemProtocol p(host);
      command_calibration(p);  // judged once calibrated
      polhem::Input in;
      in.encoder = counts_seen(unit, host, q);
      DeviceReading r;
      ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
      if (r.status != DeviceStatus::kFault) continue;  // a pose the other configuration could give
      ++caught;
      EXPECT_NE(p.fault().find(std::string("not a ") + polhem::config_name(host)), std::string::npos) << p.fault();
      std::array<std::uint8_t, 64> buf{};
      Vec3 amps;
      ASSERT_TRUE(polhem::decode_currents(std::span(buf.data() + 1, p.encode_output(Vec3{1, 1, 1}, true, 0, buf) - 1), amps));
      EXPECT_EQ(norm(amps), 0.0) << "current sent to a unit of the other configuration";
      in.encoder = polhem::encoders_for(Vec3{}, host);  // latched, even at a pose it could give
      ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
      EXPECT_EQ(r.status, DeviceStatus::kFault);
    }
    // These four poses of a v3 unit read beyond the v1's reach; a v1 unit is caught where
    // the v3 linkage cannot close (toward +x), not at its centre.
    EXPECT_EQ(caught, host == polhem::Config::kV1 ? 4 : 2) << polhem::config_name(host);
  }
}

TEST(Polhem, EmulatorSideInvertsTheHostsKinematics) {
  // encoders_for and force_from_currents (the emulator's side) against position_m and
  // motor_currents_a (the host's): a pose round-trips to within a count, a force exactly.
  for (const polhem::Config c : kConfigs)
    for (const Vec3 p : {Vec3{0, 0, 0}, Vec3{0.03, -0.02, 0.01}, Vec3{-0.04, 0.05, -0.03}}) {
      const auto e = polhem::encoders_for(p, c);
      EXPECT_LT(norm(polhem::position_m(e, c) - p), 2 * polhem::caps(c).position_resolution_m) << p.x << " " << p.y << " " << p.z;
      const Vec3 f{1.0, -2.0, 0.5};
      EXPECT_LT(norm(polhem::force_from_currents(polhem::motor_currents_a(f, e, c), e, c) - f), 1e-9);
    }
}

TEST(Polhem, SpecNamesTheConfigurationDefaultingToUpstreamsUsbExample) {
  PolhemSpec s = parse_polhem_spec("1234:0006");
  EXPECT_EQ(s.link, "1234:0006");
  EXPECT_EQ(s.config, polhem::Config::kV3);
  EXPECT_NE(polhem_config_note(s).find("polhem_v3 (the default"), std::string::npos);
  EXPECT_NE(polhem_config_note(s).find("forsslund/hfabapi @aadabaa82ce9 (2023-04-05)"), std::string::npos);
  s = parse_polhem_spec("emu:/tmp/x.sock,config=v1");
  EXPECT_EQ(s.link, "emu:/tmp/x.sock");
  EXPECT_EQ(s.config, polhem::Config::kV1);
  auto error = [](const std::string& arg) {
    try {
      parse_polhem_spec(arg);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("1234:0006,config=v2").find("config 'v2' is neither v1 nor v3"), std::string::npos);
  EXPECT_NE(error("1234:0006,kin=v1").find("unknown option 'kin=v1'"), std::string::npos);
  EXPECT_NE(error(",config=v1").find("no device"), std::string::npos);
}

// Lock-step (one report per command): the newest pose is a USB round trip old, so the
// Polhem's own stale timeout (5-10 ms) replaces the servo's two periods.
TEST(Polhem, CapsCarryALockStepStaleTimeout) {
  for (const polhem::Config c : kConfigs) {
    const DeviceCaps d = polhem::caps(c);
    EXPECT_GE(d.stale_timeout_s, 0.005);
    EXPECT_LE(d.stale_timeout_s, 0.010);
  }
  EXPECT_EQ(polhem::caps(polhem::Config::kV3).max_stiffness_n_per_m, 2000.0);  // hfab_math.h polhem_v3
  EXPECT_EQ(polhem::caps(polhem::Config::kV1).max_stiffness_n_per_m, 800.0);
}

// A force that needs more than the cap on one motor: the host scales the three currents as
// one vector (the largest exactly at the cap), so the force the unit makes keeps the
// demand's direction, only smaller. Clamping each motor alone would turn it (the motor at
// the cap gives less than its share, the others their full share).
namespace {
Vec3 unit(const Vec3& v) { return v / norm(v); }
}  // namespace

TEST(Polhem, CurrentsOverTheCapAreScaledAsOneVectorKeepingTheForcesDirection) {
  const double cap = polhem::kMaxCurrentA;
  for (const polhem::Config c : kConfigs) {
    const auto e = polhem::encoders_for(Vec3{0.01, -0.02, 0.015}, c);
    const Vec3 dir = unit(Vec3{1.0, 0.3, -0.5});
    const Vec3 per_n = polhem::motor_currents_a(dir, e, c);  // [A per N]
    const double most = std::max({std::abs(per_n.x), std::abs(per_n.y), std::abs(per_n.z)});
    const Vec3 f = dir * (1.3 * cap / most);  // its largest current is 1.3 x the cap
    const Vec3 amps = polhem::motor_currents_a(f, e, c);
    // The case that matters: one motor over the cap, another carrying current below it (a
    // per-motor clamp then turns the force; checked so the test cannot pass vacuously).
    const double a[3] = {amps.x, amps.y, amps.z};
    int over = 0, under = 0;
    for (double v : a) over += std::abs(v) > cap, under += std::abs(v) > 0.05 && std::abs(v) < cap;
    ASSERT_EQ(over, 1) << polhem::config_name(c);
    ASSERT_GE(under, 1) << polhem::config_name(c);
    const Vec3 clamped{std::clamp(amps.x, -cap, cap), std::clamp(amps.y, -cap, cap), std::clamp(amps.z, -cap, cap)};
    EXPECT_GT(norm(unit(polhem::force_from_currents(clamped, e, c)) - dir), 1e-3) << "a per-motor clamp would not turn it";

    const Vec3 lim = polhem::limit_currents_a(amps);
    const double l[3] = {lim.x, lim.y, lim.z};
    EXPECT_EQ(std::max({std::abs(l[0]), std::abs(l[1]), std::abs(l[2])}), cap) << polhem::config_name(c);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(l[i], a[i] / 1.3, 1e-12) << polhem::config_name(c) << " motor " << i;  // proportional
    const Vec3 made = polhem::force_from_currents(lim, e, c);
    EXPECT_LT(norm(unit(made) - dir), 1e-9) << polhem::config_name(c) << ": the force turned";
    EXPECT_NEAR(norm(made), norm(f) / 1.3, 1e-9);

    // On the wire: the largest motor at exactly 2000 mA, the others the scaled currents to the mA.
    Vec3 sent;
    ASSERT_TRUE(polhem::decode_currents(polhem::encode_currents(amps), sent));
    const double w[3] = {sent.x, sent.y, sent.z};
    EXPECT_EQ(std::max({std::abs(w[0]), std::abs(w[1]), std::abs(w[2])}), cap);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(w[i], l[i], 0.5e-3) << polhem::config_name(c) << " motor " << i << " on the wire";
    EXPECT_LT(norm(unit(polhem::force_from_currents(sent, e, c)) - dir), 1e-3) << "the force sent turned (beyond mA rounding)";

    // Under the cap: unchanged. Any non-finite component: all three zero.
    EXPECT_EQ(norm(polhem::limit_currents_a(amps / 2.0) - amps / 2.0), 0.0);
    for (int i = 0; i < 3; ++i) {
      double bad[3] = {a[0] / 2, a[1] / 2, a[2] / 2};
      bad[i] = i == 1 ? double(INFINITY) : double(NAN);
      EXPECT_EQ(norm(polhem::limit_currents_a(Vec3{bad[0], bad[1], bad[2]})), 0.0) << "motor " << i;
      ASSERT_TRUE(polhem::decode_currents(polhem::encode_currents(Vec3{bad[0], bad[1], bad[2]}), sent));
      EXPECT_EQ(norm(sent), 0.0) << "motor " << i;
    }
  }
}

// The firmware's info is its switch's latched flag, clear at power-up, cleared again only by
// the calibration command; its counters start at 0 wherever the handle is, and it drives any
// current it is sent. So info 0 is no proof of calibration: the protocol sends no current
// until it has itself answered an info 1 with the command and then seen info 0.
namespace {
/// The Polhem's handshake reads no feature report: a link that has none.
class NoLink final : public ReportLink {
 public:
  std::string name() const override { return "none"; }
  std::string open() override { return {}; }
  void close() override {}
  int read(std::span<std::uint8_t>, int) override { return 0; }
  bool write(std::span<const std::uint8_t>) override { return false; }
  int get_feature(std::uint8_t, std::span<std::uint8_t>) override { return -1; }
};
}  // namespace

TEST(Polhem, ProtocolSendsNoCurrentUntilItsOwnCalibrationCommandIsAcknowledged) {
  for (const polhem::Config c : kConfigs) {
    PolhemProtocol p(c);
    DeviceCaps caps;
    NoLink link;
    ASSERT_EQ(p.handshake(link, caps), "");
    std::array<std::uint8_t, 64> buf{};
    auto sent_amps = [&](const Vec3& f) {
      Vec3 amps{NAN, NAN, NAN};
      const std::size_t n = p.encode_output(f, true, 0, buf);
      EXPECT_TRUE(polhem::decode_currents(std::span(buf.data() + 1, n - 1), amps)) << "not a current command";
      return amps;
    };
    polhem::Input in;
    in.encoder = polhem::encoders_for(Vec3{0.01, 0, -0.01}, c);  // counts a calibrated unit could give
    DeviceReading r;
    // Power-up: info 0, plausible counts. Uncalibrated (not a fault), force off, zero current,
    // and it says why.
    for (int i = 0; i < 3; ++i) {
      ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
      EXPECT_EQ(r.status, DeviceStatus::kUncalibrated) << polhem::config_name(c);
      EXPECT_TRUE(r.force_off);
      EXPECT_EQ(p.fault(), PolhemProtocol::kNotCalibrated);
      EXPECT_EQ(p.pending_command(buf), 0u) << "a command sent unasked sets the counters wherever the handle is";
      EXPECT_EQ(norm(sent_amps(Vec3{1, 2, 3})), 0.0) << "current before calibration";
    }
    // The switch pressed: it asks. Still no current while it asks (its counts are not set).
    in.info = 1;
    ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
    EXPECT_EQ(r.status, DeviceStatus::kUncalibrated);
    EXPECT_EQ(norm(sent_amps(Vec3{1, 2, 3})), 0.0) << "current while it asks";
    // info 0 without our command (none sent yet): nothing proves the counters were set.
    in.info = 0;
    ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
    EXPECT_EQ(r.status, DeviceStatus::kUncalibrated);
    EXPECT_EQ(norm(sent_amps(Vec3{1, 2, 3})), 0.0);
    // It asks, we answer, it stops asking: calibrated, and the force flows.
    in.info = 1;
    ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
    ASSERT_EQ(p.pending_command(buf), 15u);
    EXPECT_EQ(buf[1 + 6], 1);  // command 1
    in.info = 0;
    ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
    EXPECT_EQ(r.status, DeviceStatus::kOk);
    EXPECT_FALSE(r.force_off);
    EXPECT_EQ(p.fault(), "");
    EXPECT_GT(norm(sent_amps(Vec3{1, 2, 3})), 0.0);
    // Docked again: it asks; the old counts stay valid until the command runs, so the force stays.
    in.info = 1;
    ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
    EXPECT_EQ(r.status, DeviceStatus::kOk);
    EXPECT_GT(norm(sent_amps(Vec3{1, 2, 3})), 0.0);
    ASSERT_EQ(p.pending_command(buf), 15u);
    // Opened again (a reconnect: it may have been power-cycled): uncalibrated until asked and answered.
    ASSERT_EQ(p.handshake(link, caps), "");
    in.info = 0;
    ASSERT_EQ(p.decode_input(polhem::encode(in), r), "");
    EXPECT_EQ(r.status, DeviceStatus::kUncalibrated);
    EXPECT_EQ(norm(sent_amps(Vec3{1, 2, 3})), 0.0) << "current after a reopen, before calibration";
  }
}
