// sdk_device.h - what the devices driven through a vendor SDK loaded at run time share: the
// library search (dlopen, an environment override), and the device base whose own device
// thread (the SDK's scheduler callback, or a thread of ours) publishes readings and applies
// the servo's latest force, with the stall rule. The servo thread only touches two
// latest-value cells.
#pragma once
#include "isotouch/servo/core_names.h"
#include <dlfcn.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "isotouch/servo/device_io.h"
#include "isotouch/servo/latest_value.h"
#include "isotouch/servo/stall_rule.h"

namespace isotouch::servo {

/// A vendor library opened with dlopen, or why not. Never closed (OpenHaptics' driver does
/// not survive being loaded a second time in one process, as CHAI3D's CPhantomDevices.cpp
/// notes), so its functions stay valid for the process's life.
struct SdkLibrary {
  void* handle = nullptr;
  std::string path;      ///< the name or path that loaded ("" if none)
  std::string searched;  ///< what was tried, in order, with dlerror()'s reason for each
  explicit operator bool() const { return handle != nullptr; }
};

/// Opens the SDK: only `$env_var` when it is set and non-empty, else each of `names` in
/// order (dlopen's search: LD_LIBRARY_PATH, the cache, /usr/lib, ...).
SdkLibrary load_sdk(const char* env_var, const std::vector<std::string>& names);

/// Looks up `name` in `lib` into `fn`; appends the name to `missing` if absent.
template <class Fn>
void sdk_symbol(const SdkLibrary& lib, const char* name, Fn& fn, std::string& missing) {
  fn = reinterpret_cast<Fn>(dlsym(lib.handle, name));
  if (!fn) missing += std::string(missing.empty() ? "" : ", ") + name;
}

/// CLOCK_MONOTONIC [ns].
std::int64_t sdk_now_ns();

/// The stall rule and the two cells between the servo thread and a device thread. The device
/// thread calls publish() with each reading and force_now() once per device period; the
/// servo thread calls read() and write_force_n() (loads and stores only).
class SdkDevice : public HapticDeviceIO {
 public:
  SdkDevice();
  DeviceReading read() override {
    reading_.load(last_read_);
    return last_read_;
  }
  /// Any thread: the newest reading (a load into a copy; read() is the servo thread's).
  DeviceReading latest() const {
    DeviceReading r;
    reading_.load(r);
    return r;
  }
  Vec3 read_position_m() override { return read().position_m; }
  std::uint32_t buttons() override { return read().buttons; }
  /// Servo thread: one store, stamped with the clock (vDSO: no syscall). A non-finite force
  /// is stored as zero; the first write after a stall is stored as zero (the servo ramps in).
  void write_force_n(const Vec3& force_n) override;
  DeviceCaps caps() const override { return caps_; }
  /// Returns the device thread's stall count. The device thread looks once a device period
  /// (device_period_s_), so the stall time it acts on is stall_s less half that period: the
  /// force is off within stall_s + half a device period of the last write (ServoThread: 2.5
  /// of its periods, and it runs no faster than the device: within 3 servo periods).
  const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) override;
  /// Servo thread: the reading the next write answers (DeviceReading::sequence).
  void answer(std::uint64_t sequence) override { answers_ = sequence; }
  /// Report-to-force latency [us]: from publishing a reading to applying the first force
  /// that answers it (handed to the SDK), one per answered reading. Read after close().
  const std::vector<double>& latencies_us() const { return latency_us_; }
  /// Times the device thread took the force off because the servo stopped writing.
  std::uint64_t stalls() const { return rule_.stalls(); }
  /// The stall time the device thread acts on [ns] (after enable_force()).
  std::int64_t stall_ns() const { return rule_.stall_ns(); }
  /// Exact zero force, the device thread stopped, the device released. Idempotent.
  virtual void close() = 0;
  /// One line for the run's summary: the device thread's periods and SDK errors, the last one.
  virtual std::string sdk_status() const = 0;

 protected:
  /// Device thread: the newest reading (received_ns: now, connection: bumped on a
  /// disconnected -> ok change).
  void publish(DeviceReading r, std::int64_t now_ns);
  /// Device thread, once per period: the force to apply now [N, isotouch device frame].
  /// Zero unless enabled and the servo wrote since enable_force(); zero once the servo has
  /// not written for the stall time (counted) until a write made after it saw the count.
  /// `on`: whether force output should be on.
  Vec3 force_now(std::int64_t now_ns, bool& on);
  /// Device thread: after open, before the first force_now().
  void reset_device_thread(std::int64_t now_ns);
  /// Device thread: the sequence of the last reading published, and of the reading the force
  /// the last force_now() returned answers (DeviceReading::sequence; 0: none).
  std::uint64_t published_sequence() const { return sequence_; }
  std::uint64_t answered_sequence() const { return answered_; }
  DeviceCaps caps_;
  double default_stall_s_ = 0.0025;  ///< when enable_force() is given none [s]
  double device_period_s_ = 0.001;   ///< how often the device thread calls force_now() [s]

 private:
  static constexpr std::size_t kPublishRing = 64;  // readings whose publish time is kept
  LatestValue<DeviceReading> reading_;
  StallRule rule_;                    // the servo's force and the stall rule (stall_rule.h)
  DeviceReading last_read_;           // servo thread: read()'s fallback
  std::uint64_t answers_ = 0;         // servo thread
  // device thread
  bool was_down_ = false;
  std::uint32_t connection_ = 0;
  std::uint64_t sequence_ = 0, answered_ = 0;
  std::array<std::int64_t, kPublishRing> published_ns_{};
  std::vector<double> latency_us_;  // capacity reserved at construction: no allocation
};

}  // namespace isotouch::servo
