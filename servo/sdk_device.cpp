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

void SdkDevice::write_force_n(const Vec3& force_n) {
  const bool ok = std::isfinite(force_n.x) && std::isfinite(force_n.y) && std::isfinite(force_n.z);
  Vec3 f = ok ? force_n : Vec3{};
  const std::uint64_t stalls = stalls_.load(std::memory_order_acquire);
  if (stalls != stalls_seen_) f = Vec3{};  // no jump back to the force before the stall
  stalls_seen_ = stalls;
  output_.store(Output{f, ++writes_, stalls, answers_});
}

const std::atomic<std::uint64_t>* SdkDevice::enable_force(bool on, double stall_s) {
  if (!(stall_s > 0) || !std::isfinite(stall_s)) stall_s = default_stall_s_;
  stall_ns_.store(std::int64_t(stall_s * 1e9), std::memory_order_relaxed);
  enabled_ns_.store(sdk_now_ns(), std::memory_order_relaxed);
  enabled_.store(on, std::memory_order_release);
  return &stalls_;
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

void SdkDevice::reset_device_thread(std::int64_t now_ns) {
  seen_count_ = output_.load().count;
  seen_at_ = now_ns;
  was_on_ = false;
}

Vec3 SdkDevice::force_now(std::int64_t now_ns, bool& on) {
  // The clock was read before the cell: a count unchanged after it means no write up to now.
  const Output o = output_.load();
  if (o.count != seen_count_) seen_count_ = o.count, seen_at_ = now_ns;
  on = enabled_.load(std::memory_order_acquire) && seen_at_ >= enabled_ns_.load(std::memory_order_relaxed);
  const bool stalled = now_ns - seen_at_ > stall_ns_.load(std::memory_order_relaxed);
  if (on && was_on_ && stalled) stalls_.fetch_add(1, std::memory_order_release);
  if (o.stalls != stalls_.load(std::memory_order_relaxed)) on = false;
  was_on_ = on;
  const bool recent = o.answers + kPublishRing > sequence_;
  if (o.answers != answered_ && o.answers != 0 && recent && latency_us_.size() < latency_us_.capacity())
    latency_us_.push_back(double(now_ns - published_ns_[o.answers % kPublishRing]) * 1e-3);
  answered_ = o.answers;
  return on ? o.force_n : Vec3{};
}

}  // namespace isotouch::servo
