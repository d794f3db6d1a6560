// double_device.h - the physics and the record shared by the SDK test doubles (libHD.so,
// libdhd.so built in the test suite): a point mass in the SDK's frame [m] held by a hand
// spring (the emulator's defaults: 0.08 kg, 300 N/m, 5 N s/m) whose target is set by a test
// or follows a hand path; every force the host commits is logged as received (the SDK's
// frame, N), with whether output was enabled and whether the device had vanished.
#pragma once
#include <time.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

namespace isotouch_double {

struct Received {
  double t_s, f[3];
  int flags;  // bit 0: output enabled, bit 1: the device had vanished
};

inline double now_s() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

class DoubleDevice {
 public:
  using Map = std::function<std::array<double, 3>(double, double, double)>;
  /// `env`: the prefix of the variables PREFIX_PATH (a hand path, t_s,x_m,y_m,z_m in
  /// isotouch's device frame, mapped into the SDK's by `to_sdk`), PREFIX_LOG (the
  /// received forces written there when the device closes) and PREFIX_VANISH_AT (seconds).
  DoubleDevice(const char* env, Map to_sdk) : env_(env), to_sdk_(std::move(to_sdk)) { log_.reserve(1 << 16); }

  void start() {
    std::lock_guard l(mu_);
    if (t0_ == 0) t0_ = now_s();  // once: a device opened again (after an unplug) keeps one clock
    x_ = v_ = f_ = {};
    load_path();
    const char* at = std::getenv((env_ + "_VANISH_AT").c_str());
    vanish_at_ = at && *at ? std::atof(at) : -1;
    if (!path_.empty()) x_ = {path_[0][1], path_[0][2], path_[0][3]};
  }
  void step(double dt) {
    std::lock_guard l(mu_);
    const double t = now_s() - t0_;
    if (!path_.empty()) target_ = path_at(t);
    if (vanish_at_ >= 0 && t >= vanish_at_) vanished_ = true, vanish_at_ = -1;
    for (int i = 0; i < 3; ++i) {
      const double a = (300.0 * (target_[i] - x_[i]) - 5.0 * v_[i] + f_[i]) / 0.08;
      v_[i] += a * dt;
      x_[i] += v_[i] * dt;
    }
  }
  /// A force the host committed [N, SDK frame]; applied while enabled and present.
  void receive(const double f[3], bool enabled) {
    std::lock_guard l(mu_);
    if (log_.size() < log_.capacity()) log_.push_back({now_s() - t0_, {f[0], f[1], f[2]}, (enabled ? 1 : 0) | (vanished_ ? 2 : 0)});
    for (int i = 0; i < 3; ++i) f_[i] = enabled && !vanished_ ? f[i] : 0.0;
  }
  std::array<double, 3> position() { std::lock_guard l(mu_); return x_; }
  std::array<double, 3> velocity() { std::lock_guard l(mu_); return v_; }
  void set_target(const double p[3]) { std::lock_guard l(mu_); target_ = {p[0], p[1], p[2]}; path_.clear(); }
  void vanish(bool on) { std::lock_guard l(mu_); vanished_ = on; }
  bool vanished() { std::lock_guard l(mu_); return vanished_; }
  int copy_log(double* out, int max) {
    std::lock_guard l(mu_);
    int n = 0;
    for (const Received& r : log_) {
      if (n >= max) break;
      double* o = out + 5 * n++;
      o[0] = r.t_s, o[1] = r.f[0], o[2] = r.f[1], o[3] = r.f[2], o[4] = r.flags;
    }
    return int(log_.size());
  }
  void clear_log() { std::lock_guard l(mu_); log_.clear(); }
  /// CLOCK_MONOTONIC of the log's 0 s [s] (0: not started).
  double start_s() { std::lock_guard l(mu_); return t0_; }
  /// Writes PREFIX_LOG if set: t_s,fx_n,fy_n,fz_n,enabled,vanished (SDK frame).
  void write_log() {
    const char* file = std::getenv((env_ + "_LOG").c_str());
    if (!file || !*file) return;
    std::lock_guard l(mu_);
    std::ofstream o(file);
    o.precision(17);  // the forces as received, to the last bit
    o << "t_s,fx_n,fy_n,fz_n,enabled,vanished\n";
    for (const Received& r : log_)
      o << r.t_s << ',' << r.f[0] << ',' << r.f[1] << ',' << r.f[2] << ',' << (r.flags & 1) << ',' << (r.flags >> 1 & 1) << '\n';
  }

 private:
  void load_path() {
    path_.clear();
    const char* file = std::getenv((env_ + "_PATH").c_str());
    if (!file || !*file) return;
    std::ifstream in(file);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      double t, x, y, z;
      if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf", &t, &x, &y, &z) != 4) continue;
      const auto p = to_sdk_(x, y, z);
      path_.push_back({t, p[0], p[1], p[2]});
    }
  }
  std::array<double, 3> path_at(double t) const {
    const double end = path_.back()[0];
    if (end > 0) t = std::fmod(t, end);
    std::size_t i = std::size_t(t / 0.001);  // rows every ms
    if (i >= path_.size()) i = path_.size() - 1;
    return {path_[i][1], path_[i][2], path_[i][3]};
  }

  std::string env_;
  Map to_sdk_;
  std::mutex mu_;
  double t0_ = 0;
  std::array<double, 3> x_{}, v_{}, f_{}, target_{};
  std::vector<std::array<double, 4>> path_;
  std::vector<Received> log_;
  bool vanished_ = false;
  double vanish_at_ = -1;  // PREFIX_VANISH_AT [s since start]: the device vanishes then
};

}  // namespace isotouch_double
