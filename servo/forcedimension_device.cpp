#include "isotouch/servo/forcedimension_device.h"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "isotouch/servo/cpu_placement.h"

namespace isotouch::servo {
namespace {
void sleep_until_ns(std::int64_t t) {
  const timespec ts{time_t(t / 1000000000LL), long(t % 1000000000LL)};
  clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

struct SystemSpec {
  const char* name;
  double force_n, stiffness_n_per_m, damping_n_s_per_m, radius_m;
  int buttons;
};

/// CHAI3D's cDeltaDevice::open() table (CDeltaDevices.cpp at 7c76b1f2).
SystemSpec spec_of(int type) {
  switch (type) {
    case dhd::kDelta3: case 111: return {"delta.3", 20, 5000, 30, 0.15, 1};
    case dhd::kOmega3: case 110: return {"omega.3", 12, 5000, 30, 0.075, 1};
    case dhd::kOmega6Right: return {"omega.6R", 12, 5000, 30, 0.075, 1};
    case dhd::kOmega6Left: return {"omega.6L", 12, 5000, 30, 0.075, 1};
    case dhd::kOmega7Right: return {"omega.7R", 12, 5000, 30, 0.075, 1};
    case dhd::kOmega7Left: return {"omega.7L", 12, 5000, 30, 0.075, 1};
    case dhd::kSigma7Right: case 102: case 209: return {"sigma.7R", 12, 4000, 30, 0.075, 1};
    case dhd::kSigma7Left: case 103: return {"sigma.7L", 12, 4000, 30, 0.075, 1};
    case dhd::kLambda7Right: return {"lambda.7R", 12, 8000, 30, 0.1125, 1};
    case dhd::kLambda7Left: return {"lambda.7L", 12, 8000, 30, 0.1125, 1};
    case dhd::kFalcon: return {"Novint Falcon", 8, 3000, 20, 0.04, 4};
  }
  return {"Force Dimension device (unknown type: omega.3 limits)", 12, 5000, 30, 0.075, 1};
}
}  // namespace

std::string load_dhd_api(DhdApi& a) {
  a.lib = load_sdk("ISOTOUCH_DHD_LIBRARY", {"libdhd.so", "libdhd.so.3"});
  if (!a.lib) return "Force Dimension SDK library not found (searched: " + a.lib.searched + ")";
  std::string missing, optional;
  sdk_symbol(a.lib, "dhdGetDeviceCount", a.dhdGetDeviceCount, missing);
  sdk_symbol(a.lib, "dhdOpenID", a.dhdOpenID, missing);
  sdk_symbol(a.lib, "dhdClose", a.dhdClose, missing);
  sdk_symbol(a.lib, "dhdGetSystemType", a.dhdGetSystemType, missing);
  sdk_symbol(a.lib, "dhdGetPosition", a.dhdGetPosition, missing);
  sdk_symbol(a.lib, "dhdGetButtonMask", a.dhdGetButtonMask, missing);
  sdk_symbol(a.lib, "dhdSetForce", a.dhdSetForce, missing);
  sdk_symbol(a.lib, "dhdEnableForce", a.dhdEnableForce, missing);
  sdk_symbol(a.lib, "dhdErrorGetLastStr", a.dhdErrorGetLastStr, optional);
  sdk_symbol(a.lib, "dhdEnableExpertMode", a.dhdEnableExpertMode, optional);
  sdk_symbol(a.lib, "dhdSetWatchdog", a.dhdSetWatchdog, optional);
  sdk_symbol(a.lib, "dhdGetStatus", a.dhdGetStatus, optional);
  if (!missing.empty()) return a.lib.path + " lacks " + missing + " (not the Force Dimension DHD library?)";
  return {};
}

DeviceCaps dhd_system_caps(int type) {
  const SystemSpec s = spec_of(type);
  DeviceCaps c;
  c.name = s.name;
  c.max_force_n = s.force_n;
  c.max_stiffness_n_per_m = s.stiffness_n_per_m;
  c.max_damping_n_s_per_m = s.damping_n_s_per_m;
  c.workspace_min_m = Vec3{-s.radius_m, -s.radius_m, -s.radius_m};  // the box around CHAI3D's sphere
  c.workspace_max_m = Vec3{s.radius_m, s.radius_m, s.radius_m};
  c.buttons = s.buttons;
  return c;
}

ForceDimensionDevice::ForceDimensionDevice(int index, double rate_hz) : index_(index), rate_hz_(rate_hz) {}

ForceDimensionDevice::~ForceDimensionDevice() { close(); }

void ForceDimensionDevice::note_error(const char* call) {
  errors_.fetch_add(1);
  const char* why = api_.dhdErrorGetLastStr ? api_.dhdErrorGetLastStr() : nullptr;
  std::lock_guard lock(note_mu_);
  last_error_ = std::string(call) + " failed" + (why ? std::string(": ") + why : std::string(" (-1)"));
}

std::string ForceDimensionDevice::last_error() const {
  std::lock_guard lock(note_mu_);
  return last_error_;
}

std::string ForceDimensionDevice::sdk_status() const {
  const std::string last = last_error();
  return std::to_string(periods()) + " device periods, " + std::to_string(errors()) + " dhd errors" +
         (last.empty() ? "" : " (last: " + last + ")");
}

void ForceDimensionDevice::open() {
  if (thread_.joinable()) return;
  const std::string who = "forcedimension:" + std::to_string(index_);
  if (!api_.lib)
    if (const std::string e = load_dhd_api(api_); !e.empty()) throw std::runtime_error("--haptic forcedimension: " + e);
  const int count = api_.dhdGetDeviceCount();
  if (index_ < 0 || index_ >= count)
    throw std::runtime_error(who + ": no such device (" + std::to_string(count < 0 ? 0 : count) + " found by " +
                             api_.lib.path + ")");
  const int id = api_.dhdOpenID(char(index_));
  if (id < 0) {
    note_error("dhdOpenID");
    throw std::runtime_error(who + ": " + last_error());
  }
  id_ = char(id);
  const int type = api_.dhdGetSystemType(id_);
  caps_ = dhd_system_caps(type);
  caps_.native_rate_hz = rate_hz_;
  // The device thread applies each force once a period: a servo faster than it is refused,
  // and the stall rule acts in its periods (SdkDevice::enable_force).
  caps_.output_rate_hz = rate_hz_;
  device_period_s_ = 1.0 / rate_hz_;
  set_watchdog(true);
  const std::string watchdog = caps_.watchdog_s > 0
                                   ? "firmware watchdog " + std::to_string(int(std::lround(caps_.watchdog_s * 1e3))) + " ms"
                                   : "no firmware watchdog (the SDK has no dhdSetWatchdog: SDK 3.3.2 or later sets one)";
  description_ = who + " (" + caps_.name + ", system type " + std::to_string(type) + ", " + watchdog +
                 (api_.dhdGetStatus ? "" : ", no dhdGetStatus: a force-off by the firmware is not seen") + ", " +
                 api_.lib.path + ")";
  status_every_ = std::max(1, int(std::lround(rate_hz_ / 1000.0)));
  stop_ = false;
  thread_ = std::thread([this] { loop(); });
  for (int i = 0; i < 1000 && periods_.load() == 0; ++i) sleep_until_ns(sdk_now_ns() + 1'000'000);
}

/// The firmware's own watchdog (dhdSetWatchdog, in 125 us units): forces off when no force
/// command came for max(10 device periods, 10 ms), so a killed or hung isotouch leaves no force
/// on. The device thread commands a force every period. CHAI3D enables expert mode first.
void ForceDimensionDevice::set_watchdog(bool record) {
  if (!api_.dhdSetWatchdog) return;  // an SDK before 3.3.2: said in the description
  const double want_s = std::max(10.0 / rate_hz_, 0.010);
  const double units = std::clamp(std::ceil(want_s / (dhd::kWatchdogUnitUs * 1e-6)), 1.0, double(dhd::kWatchdogMax));
  if (api_.dhdEnableExpertMode) api_.dhdEnableExpertMode();
  if (api_.dhdSetWatchdog((unsigned char)units, id_) < 0) return note_error("dhdSetWatchdog");
  if (record) caps_.watchdog_s = units * dhd::kWatchdogUnitUs * 1e-6;
}

std::string ForceDimensionDevice::realtime_note() const {
  std::lock_guard lock(note_mu_);
  return realtime_note_;
}

void ForceDimensionDevice::close() {
  if (!thread_.joinable()) return;
  stop_ = true;
  thread_.join();
}

/// Device thread, while the device is gone: every 100 ms, close its old ID and open the index
/// again (an unplugged device's ID stays invalid after it is plugged back); the watchdog is set
/// again on the new ID. Force output starts off (force_on false): the servo ramps in.
void ForceDimensionDevice::reopen(std::int64_t now, bool& force_on) {
  if (now - last_reopen_ns_ < 100'000'000) return;
  last_reopen_ns_ = now;
  api_.dhdClose(id_);
  const int id = api_.dhdOpenID(char(index_));
  if (id < 0) return;  // not back yet
  id_ = char(id);
  force_on = false;
  fw_off_ = false;  // opened anew: its force state starts off, and the servo ramps in
  set_watchdog(false);  // caps_ keeps what open() set (other threads read it)
  reopens_.fetch_add(1);
}

void ForceDimensionDevice::period(std::int64_t now, bool& force_on) {
  double x = 0, y = 0, z = 0;
  DeviceReading r;
  if (down_) reopen(now, force_on);
  if (api_.dhdGetPosition(&x, &y, &z, id_) < 0) {
    if (!down_) note_error("dhdGetPosition"), last_reopen_ns_ = now;
    down_ = true;
    r.status = DeviceStatus::kDisconnected;  // the servo holds; we send zero below
    r.position_m = last_position_;
  } else {
    down_ = false;
    r.position_m = last_position_ = dhd_to_device_m(x, y, z);
    r.buttons = api_.dhdGetButtonMask(id_);
    if (periods_.load(std::memory_order_relaxed) % status_every_ == 0) read_status(force_on);
  }
  r.force_off = !force_on;  // also while the firmware has them off (read_status)
  r.watchdog_tripped = fw_off_ && fw_off_cause_ == dhd::kForceOffWatchdog;
  publish(r, now);
  if (fw_off_ && fw_off_reading_ == 0) fw_off_reading_ = published_sequence();
  bool on = false;
  // The stall is judged at the clock of this look, after the device's reads (USB time): a
  // stall that came due during them is acted on now, not a device period later.
  Vec3 f = force_now(sdk_now_ns(), on);
  if (down_) on = false;
  if (fw_off_) {
    // Back on (below: dhdEnableForce) once the servo's force is an exact zero answering a
    // reading that said force_off, and, unless the watchdog turned them off, once the user
    // turned them on again at the device.
    const bool servo_zero = answered_sequence() >= fw_off_reading_ && f.x == 0.0 && f.y == 0.0 && f.z == 0.0;
    if (servo_zero && (fw_off_cause_ == dhd::kForceOffWatchdog || fw_on_)) fw_off_ = false;
    else on = false;
  }
  if (on != force_on && api_.dhdEnableForce(on ? dhd::kOn : dhd::kOff, id_) >= 0) force_on = on;
  if (!on) f = Vec3{};
  const Vec3 fd = device_to_dhd_force(f);
  if (api_.dhdSetForce(fd.x, fd.y, fd.z, id_) < 0 && !down_) note_error("dhdSetForce");
}

/// Device thread: the firmware's force state (dhdGetStatus). Forces off while this thread has
/// them on: the firmware turned them off by itself (its watchdog: this thread starved past
/// watchdog_s(); a button, a velocity or deadman switch): counted, noted, and held off
/// (period()) with `force_on` cleared, so readings say force_off and the servo holds its ramp.
void ForceDimensionDevice::read_status(bool& force_on) {
  if (!api_.dhdGetStatus) return;
  int st[dhd::kMaxStatus] = {};
  if (api_.dhdGetStatus(st, id_) < 0) return;  // a device going away: dhdGetPosition says so
  fw_on_ = st[dhd::kStatusForce] != 0;
  if (!force_on || fw_on_ || fw_off_) return;
  fw_off_ = true;
  fw_off_cause_ = st[dhd::kStatusForceOffCause];
  fw_off_reading_ = 0;
  force_on = false;  // the firmware's state; dhdEnableForce(DHD_ON) turns them on again
  force_offs_.fetch_add(1);
  const bool watchdog = fw_off_cause_ == dhd::kForceOffWatchdog;
  if (watchdog) watchdog_trips_.fetch_add(1);
  std::lock_guard lock(note_mu_);
  last_error_ = watchdog ? "the firmware's watchdog turned the forces off (no force command within " +
                               std::to_string(int(std::lround(caps_.watchdog_s * 1e3))) +
                               " ms: the device thread was starved); on again from zero"
                         : "the device turned the forces off (cause " + std::to_string(fw_off_cause_) +
                               ": a button, a velocity or deadman switch); on again from zero once the device is";
}

void ForceDimensionDevice::loop() {
  // The servo's priority where the system allows it (root, CAP_SYS_NICE): this thread applies
  // its forces. Refused: the default scheduler, said by realtime_note().
  const std::string note = make_thread_realtime("forcedimension device thread", true, 80, false, -1).note;
  {
    std::lock_guard lock(note_mu_);
    realtime_note_ = note;
  }
  const auto step = std::int64_t(1e9 / rate_hz_);
  std::int64_t next = sdk_now_ns();
  reset_device_thread(next);
  bool force_on = false;
  while (!stop_.load()) {
    period(sdk_now_ns(), force_on);
    periods_.fetch_add(1);
    next += step;
    sleep_until_ns(next);
  }
  api_.dhdSetForce(0.0, 0.0, 0.0, id_);  // exact zero, then off
  api_.dhdEnableForce(dhd::kOff, id_);
  api_.dhdClose(id_);
}

}  // namespace isotouch::servo

namespace isotouch::servo {
std::vector<std::string> list_forcedimension(const DhdApi& a) {
  const int n = a.dhdGetDeviceCount();
  std::vector<std::string> out;
  if (n <= 0) out.push_back("no device (dhdGetDeviceCount: " + std::to_string(n) + ")");
  for (int i = 0; i < n; ++i) {
    const int id = a.dhdOpenID(char(i));
    if (id < 0) {
      out.push_back(std::to_string(i) + ": cannot open (" +
                    (a.dhdErrorGetLastStr ? a.dhdErrorGetLastStr() : "dhdOpenID -1") + ")");
      continue;
    }
    const int type = a.dhdGetSystemType(char(id));
    out.push_back(std::to_string(i) + ": " + dhd_system_caps(type).name + " (system type " + std::to_string(type) + ")");
    a.dhdClose(char(id));
  }
  return out;
}
}  // namespace isotouch::servo
