// dhd_double.cpp - a test double of the Force Dimension DHD library (built as libdhd.so):
// the dhd functions isotouch calls, with the SDK's units and conventions (m, N; x toward
// the user, y right, z up; -1 on error, the device ID last), one delta.3 (system type 63)
// whose physics runs on the double's own 1 kHz clock (the device's; kept light: the host's CPUs are the servo's), calls that take USB
// time (50 us), and a device that vanishes (every call fails, the count drops to 0).
// Declarations from isotouch/servo/dhd_api.h (from CHAI3D's CDeltaDevices.cpp, cited there).
// Test controls: dhdDouble* below. Environment: DHD_DOUBLE_PATH, DHD_DOUBLE_LOG (double_device.h).
#include <pthread.h>

#include <atomic>
#include <map>
#include <thread>

#include "isotouch/servo/dhd_api.h"
#include "isotouch/tests/sdk_doubles/double_device.h"

using isotouch_double::DoubleDevice;

namespace {
// Isotouch's device frame (x right, y away from the user, z up) -> Force Dimension's [m].
DoubleDevice g_dev("DHD_DOUBLE", [](double x, double y, double z) { return std::array<double, 3>{-y, x, z}; });
std::atomic<bool> g_open{false}, g_force_on{false}, g_running{false};
std::atomic<long> g_bad_ids{0};
std::atomic<bool> g_expert{false};
// An unplugged device's ID stays invalid after it is back, until it is closed and opened again
// (as the SDK's handles do); opens counted.
std::atomic<bool> g_stale_id{false};
std::atomic<long> g_opens{0};
std::atomic<int> g_watchdog{0};
// The firmware's watchdog, run by the double's clock once a test arms it (dhdDoubleArmWatchdog:
// off by default, so a loaded machine's starved device thread trips nothing in other tests):
// forces off, cause DHD_FORCEOFF_WATCHDOG, when no dhdSetForce came for g_watchdog x 125 us.
std::atomic<bool> g_watchdog_armed{false};
std::atomic<double> g_last_force_s{0};
std::atomic<int> g_force_off_cause{0};  // status[DHD_STATUS_FORCEOFFCAUSE]
std::atomic<long> g_watchdog_trips{0}, g_enables{0};
std::atomic<int> g_starve_ms{0};  // the next dhdGetPosition takes this long (a starved device thread)
std::thread g_clock;
std::atomic<const char*> g_error{"no error"};
std::mutex g_callers_mu;
std::map<unsigned long, long> g_callers;  // pthread_self() -> dhd calls made on it

void usb_time() {
  {
    std::lock_guard l(g_callers_mu);
    ++g_callers[static_cast<unsigned long>(pthread_self())];
  }
  std::this_thread::sleep_for(std::chrono::microseconds(50));
}
bool usable(char id) {
  if (id != 0) {
    g_bad_ids.fetch_add(1);
    g_error = "invalid device ID";
    return false;
  }
  if (!g_open.load()) g_error = "device not open";
  else if (g_dev.vanished()) g_error = "communication error (device unplugged)";
  else if (g_stale_id.load()) g_error = "communication error (the device was unplugged: open it again)";
  else return true;
  return false;
}
// Literal values of the vendor's dhdc.h (SDK 3.10.0: DHD_STATUS_FORCE 5,
// DHD_STATUS_FORCEOFFCAUSE 14, DHD_FORCEOFF_WATCHDOG 3, DHD_FORCEOFF_SOFTWARE 4; source cited in
// isotouch/servo/dhd_api.h), not isotouch's constants: a wrong constant there is caught here.
constexpr int kVendorStatusForce = 5, kVendorStatusForceOffCause = 14, kVendorForceOffWatchdog = 3,
              kVendorForceOffSoftware = 4;
void trip_watchdog() {
  if (g_force_on.exchange(false)) {
    g_force_off_cause = kVendorForceOffWatchdog;
    g_watchdog_trips.fetch_add(1);
  }
}
void clock_loop() {
  double next = isotouch_double::now_s();
  while (g_running.load()) {
    g_dev.step(0.001);
    const int wd = g_watchdog.load();
    if (g_watchdog_armed.load() && wd > 0 && g_force_on.load() &&
        isotouch_double::now_s() - g_last_force_s.load() > wd * 125e-6)
      trip_watchdog();
    next += 0.001;
    const double wait = next - isotouch_double::now_s();
    if (wait > 0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
  }
}
}  // namespace

extern "C" {
int dhdGetDeviceCount(void) { return g_dev.vanished() ? 0 : 1; }
int dhdOpenID(char id) {
  if (id != 0 || g_dev.vanished() || g_open.load()) {
    g_error = "no such device, or already open";
    return -1;
  }
  g_dev.start();
  g_open = true;
  g_stale_id = false;
  g_opens.fetch_add(1);
  g_running = true;
  g_clock = std::thread(clock_loop);
  return 0;
}
int dhdClose(char id) {
  if (id != 0 || !g_open.exchange(false)) return -1;
  g_running = false;
  g_clock.join();
  g_dev.write_log();
  return 0;
}
int dhdGetSystemType(char id) { return usable(id) ? 63 : -1; }  // DHD_DEVICE_DELTA3
int dhdGetPosition(double* px, double* py, double* pz, char id) {
  usb_time();
  if (const int ms = g_starve_ms.exchange(0); ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(ms));
  if (!usable(id)) return -1;
  const auto p = g_dev.position();
  *px = p[0], *py = p[1], *pz = p[2];
  return 0;
}
unsigned int dhdGetButtonMask(char id) { return usable(id) ? 0u : 0u; }
int dhdSetForce(double fx, double fy, double fz, char id) {
  usb_time();
  if (id != 0 || !g_open.load()) return -1;
  const double f[3] = {fx, fy, fz};
  g_dev.receive(f, g_force_on.load());  // logged also when vanished (flagged): what the host sent
  g_last_force_s = isotouch_double::now_s();
  return g_dev.vanished() || g_stale_id.load() ? -1 : 0;
}
int dhdEnableForce(unsigned char val, char id) {
  if (!usable(id)) return -1;
  if (val != 0) {
    g_last_force_s = isotouch_double::now_s();  // the watchdog counts from here
    if (!g_force_on.load()) g_enables.fetch_add(1);
  } else if (g_force_on.load()) {
    g_force_off_cause = kVendorForceOffSoftware;
  }
  g_force_on = val != 0;
  return 0;
}
/// The vendor's int status[DHD_MAX_STATUS] (16 in 3.10, 17 later; isotouch passes 17): power
/// and connection on, forces, and the cause of the last force-off.
int dhdGetStatus(int* status, char id) {
  if (!usable(id)) return -1;
  for (int i = 0; i < 16; ++i) status[i] = 0;
  status[0] = status[1] = 1;  // DHD_STATUS_POWER, DHD_STATUS_CONNECTED
  status[kVendorStatusForce] = g_force_on.load() ? 1 : 0;
  status[kVendorStatusForceOffCause] = g_force_off_cause.load();
  return 0;
}
const char* dhdErrorGetLastStr(void) { return g_error; }
int dhdEnableExpertMode(void) {
  g_expert = true;
  return 0;
}
/// The firmware's watchdog: val x 125 us without a force command disables forces (0: off).
/// Expert mode first, as CHAI3D does.
int dhdSetWatchdog(unsigned char val, char id) {
  if (!usable(id) || !g_expert.load()) return -1;
  g_watchdog = val;
  return 0;
}

// Test controls.
void dhdDoubleVanish(int on) {
  if (on) g_stale_id = true;
  g_dev.vanish(on != 0);
}
/// dhdOpenID calls that opened the device.
long dhdDoubleOpens() { return g_opens.load(); }
void dhdDoubleSetTarget(const double m[3]) { g_dev.set_target(m); }
/// As hdDoubleLog (hd_double.cpp), forces in the FD frame [N].
int dhdDoubleLog(double* out, int max) { return g_dev.copy_log(out, max); }
void dhdDoubleClearLog() { g_dev.clear_log(); }
/// 1 while force output is enabled (dhdEnableForce(DHD_ON)).
int dhdDoubleForceOn() { return g_force_on.load() ? 1 : 0; }
long dhdDoubleBadIds() { return g_bad_ids.load(); }
/// CLOCK_MONOTONIC of the log's 0 s [s].
double dhdDoubleStartS() { return g_dev.start_s(); }
/// The watchdog value set (125 us units; 0: none).
int dhdDoubleWatchdog() { return g_watchdog.load(); }
/// Arms (1) or disarms (0) the firmware watchdog's timing on the double's clock.
void dhdDoubleArmWatchdog(int on) {
  g_last_force_s = isotouch_double::now_s();
  g_watchdog_armed = on != 0;
}
/// The next dhdGetPosition takes `ms` milliseconds: the device thread starved that long.
void dhdDoubleStarve(int ms) { g_starve_ms = ms; }
/// The firmware watchdog trips now (forces off, cause DHD_FORCEOFF_WATCHDOG) if forces are on.
void dhdDoubleTripWatchdog() { trip_watchdog(); }
/// The user presses the device's force button: forces off (cause DHD_FORCEOFF_BUTTON, 1) or
/// on again.
void dhdDoubleForceButton(int on) {
  if (on) g_force_on = true;
  else if (g_force_on.exchange(false)) g_force_off_cause = 1;
}
/// Times the watchdog turned the forces off; times dhdEnableForce turned them on.
long dhdDoubleWatchdogTrips() { return g_watchdog_trips.load(); }
long dhdDoubleEnables() { return g_enables.load(); }
/// dhdGetPosition and dhdSetForce calls made on the thread whose pthread_self() is `thread`.
long dhdDoubleCallsOn(unsigned long thread) {
  std::lock_guard l(g_callers_mu);
  const auto it = g_callers.find(thread);
  return it == g_callers.end() ? 0 : it->second;
}
}
