// test_device_refusals.cpp - a scene whose renderer exceeds what the device declares is
// refused when the device is opened (run::open_haptic_device), naming the scene's field, its
// value and the device's bound, for every backend that declares a stiffness bound: the v1
// and Polhem emulators (their capabilities over the socket) and the OpenHaptics and Force
// Dimension test doubles (their SDK calls). The bound comes from the device, not this test.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>

#include "isotouch/io/scene.h"
#include "isotouch/run/haptic_device.h"
#include "isotouch/sim/device_emulator.h"

namespace {

using isotouch::run::DeviceSetup;

/// An emulator serving one socket on its own thread until the object goes.
struct Emulator {
  std::unique_ptr<isotouch::sim::DeviceEmulator> emu;
  std::thread thread;
  explicit Emulator(bool polhem) {
    isotouch::sim::EmuConfig c;
    c.polhem = polhem;
    c.socket_path = "/tmp/isotouch-test-refusals-" + std::to_string(::getpid()) + ".sock";
    c.seconds = 0;
    c.caps.name = "test-emu";
    c.caps.max_force_n = 10;
    c.caps.max_stiffness_n_per_m = 2000;
    c.caps.watchdog_s = 0.05;
    emu = std::make_unique<isotouch::sim::DeviceEmulator>(c);
    emu->listen();
    thread = std::thread([this] { emu->run(); });
  }
  ~Emulator() {
    emu->stop();
    thread.join();
  }
  std::string socket() const { return "/tmp/isotouch-test-refusals-" + std::to_string(::getpid()) + ".sock"; }
};

/// What open_haptic_device says for `spec` with a renderer of `stiffness` [N/m] ("" if it opened).
std::string refusal(const std::string& spec, double stiffness) {
  isotouch::io::Scene scene;
  scene.hri.stiffness_n_per_m = stiffness;
  scene.hri.damping_n_s_per_m = 0, scene.hri.force_limit_n = 1;  // within every device's: only K is judged
  DeviceSetup ds;
  ds.scene = &scene;
  ds.hri = scene.hri;
  try {
    isotouch::run::HapticDevice d = isotouch::run::open_haptic_device(spec, ds, 0);
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

/// The device's bound from its own caps, opened with a stiffness every device takes.
double device_bound(const std::string& spec) {
  isotouch::io::Scene scene;
  scene.hri.stiffness_n_per_m = 1;
  scene.hri.damping_n_s_per_m = 0, scene.hri.force_limit_n = 1;
  DeviceSetup ds;
  ds.scene = &scene;
  ds.hri = scene.hri;
  isotouch::run::HapticDevice d = isotouch::run::open_haptic_device(spec, ds, 0);
  return d.io->caps().max_stiffness_n_per_m;
}

void expect_refused_over_the_bound(const std::string& spec) {
  const double bound = device_bound(spec);
  ASSERT_TRUE(bound > 0 && bound < 1e9) << spec << " declares no stiffness bound";
  EXPECT_EQ(refusal(spec, bound), "") << spec << " refused a scene at its bound";
  const std::string why = refusal(spec, 2 * bound);
  EXPECT_NE(why.find("servo.stiffness_n_per_m"), std::string::npos) << spec << ": '" << why << "'";
  EXPECT_NE(why.find("exceeds the device's maximum stiffness"), std::string::npos) << spec << ": '" << why << "'";
}

}  // namespace

TEST(DeviceRefusals, OpenHapticsRefusesAStiffnessOverItsBound) {
  setenv("ISOTOUCH_HD_LIBRARY", HD_DOUBLE, 1);
  expect_refused_over_the_bound("openhaptics");
}

TEST(DeviceRefusals, ForceDimensionRefusesAStiffnessOverItsBound) {
  setenv("ISOTOUCH_DHD_LIBRARY", DHD_DOUBLE, 1);
  expect_refused_over_the_bound("forcedimension");
}

TEST(DeviceRefusals, AV1DeviceRefusesAStiffnessOverItsBound) {
  Emulator e(false);
  expect_refused_over_the_bound("emu:" + e.socket());
}

TEST(DeviceRefusals, APolhemRefusesAStiffnessOverItsBound) {
  Emulator e(true);
  expect_refused_over_the_bound("polhem:emu:" + e.socket());
}
