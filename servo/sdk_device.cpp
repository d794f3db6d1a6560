#include "isotouch/servo/sdk_device.h"

#include <dlfcn.h>
#include <time.h>

#include <cmath>
#include <cstdlib>

namespace isotouch::servo {

std::int64_t sdk_now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

SdkLibrary load_sdk(const char* env_var, const std::vector<std::string>& names) {
  SdkLibrary lib;
  const char* over = std::getenv(env_var);
  std::vector<std::string> tries;
  if (over && *over) {
    tries.push_back(over);
    lib.searched = std::string("$") + env_var + "=" + over;
  } else {
    tries = names;
    lib.searched = std::string("$") + env_var + " unset";
  }
  for (const std::string& name : tries) {
    dlerror();
    lib.handle = dlopen(name.c_str(), RTLD_NOW | RTLD_GLOBAL);
    if (lib.handle) {
      lib.path = name;
      return lib;
    }
    const char* err = dlerror();
    std::string why = err ? err : "not found";
    if (why.rfind(name + ": ", 0) == 0) why.erase(0, name.size() + 2);  // dlerror() names the file too
    lib.searched += "; " + name + ": " + why;
  }
  return lib;
}

SdkDevice::SdkDevice() {
  latency_us_.reserve(1 << 20);  // 17 min at 1 kHz; later answers are not measured
  DeviceReading r;
  r.status = DeviceStatus::kDisconnected;
  reading_.store(r);
  last_read_ = r;
}

void SdkDevice::write_force_n(const Vec3& force_n) { rule_.write(force_n, answers_, sdk_now_ns()); }

const std::atomic<std::uint64_t>* SdkDevice::enable_force(bool on, double stall_s) {
  return rule_.enable(on, stall_s, default_stall_s_, sdk_now_ns(), device_period_s_);
}

void SdkDevice::publish(DeviceReading r, std::int64_t now_ns) {
  if (r.status == DeviceStatus::kDisconnected) was_down_ = true;
  if (r.status == DeviceStatus::kOk && was_down_) ++connection_, was_down_ = false;
  r.received_ns = now_ns;
  r.connection = connection_;
  r.sequence = ++sequence_;
  published_ns_[sequence_ % kPublishRing] = now_ns;  // a new one: the servo ramps the force in
  reading_.store(r);
}

void SdkDevice::reset_device_thread(std::int64_t now_ns) { rule_.restart(now_ns); }

Vec3 SdkDevice::force_now(std::int64_t now_ns, bool& on) {
  // The clock was read before the cell (StallRule::look).
  const StallLook l = rule_.look(now_ns);
  on = l.on;
  const bool recent = l.answers + kPublishRing > sequence_;
  if (l.answers != answered_ && l.answers != 0 && recent && latency_us_.size() < latency_us_.capacity())
    latency_us_.push_back(double(now_ns - published_ns_[l.answers % kPublishRing]) * 1e-3);
  answered_ = l.answers;
  return l.force_n;
}

}  // namespace isotouch::servo
