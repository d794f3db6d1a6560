#include "isotouch/sim/device_emulator.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/hid_report.h"
#include "isotouch/sim/playback_device_io.h"

namespace isotouch::sim {
namespace {
std::int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}
void sleep_until(std::int64_t t) {
  const timespec ts{time_t(t / 1000000000LL), long(t % 1000000000LL)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}
constexpr std::size_t kSentRing = 1 << 14;
}  // namespace

DeviceEmulator::DeviceEmulator(EmuConfig config)
    : cfg_(std::move(config)), dev_(cfg_.device, cfg_.path.empty() ? cfg_.hold_m : cfg_.path.front().p_m),
      rng_(cfg_.faults.seed), sent_ns_(kSentRing, 0) {
  if (!(cfg_.rate_hz >= 1 && cfg_.rate_hz <= 8000))
    throw std::invalid_argument("device emulator: rate " + std::to_string(cfg_.rate_hz) + " Hz is not in [1, 8000]");
  stats_.latency_us.reserve(std::size_t(std::max(1.0, cfg_.seconds) * cfg_.rate_hz) + 16);
  log_.resize(cfg_.output_log_size);
  if (cfg_.polhem) cfg_.caps = servo::hid::polhem::caps(cfg_.polhem_config);  // its firmware's: 0.5 s watchdog, limits
  // The switch's flag: clear at power-up (the firmware's), set from the start otherwise.
  polhem_flag_ = !cfg_.polhem_power_up;
  if (cfg_.polhem && cfg_.polhem_power_up)
    polhem_power_up_counts_ = servo::hid::polhem::encoders_for(cfg_.polhem_power_up_m.value_or(dev_.position()), cfg_.polhem_config);
}

DeviceEmulator::~DeviceEmulator() {
  close_host();
  close_listener();
}

void DeviceEmulator::listen() {
  if (listen_fd_ >= 0) return;
  sockaddr_un addr{};
  if (cfg_.socket_path.empty() || cfg_.socket_path.size() >= sizeof(addr.sun_path))
    throw std::runtime_error("device emulator: socket path '" + cfg_.socket_path + "' is empty or longer than " +
                             std::to_string(sizeof(addr.sun_path) - 1) + " bytes");
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, cfg_.socket_path.c_str(), cfg_.socket_path.size() + 1);
  // A stale socket (an emulator that was killed) is replaced; anything else is kept.
  struct stat st {};
  if (::lstat(cfg_.socket_path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode))
      throw std::runtime_error("device emulator: " + cfg_.socket_path +
                               " exists and is not a socket: not replaced (choose another socket path)");
    ::unlink(cfg_.socket_path.c_str());
  }
  listen_fd_ = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (listen_fd_ < 0 || ::bind(listen_fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::listen(listen_fd_, 1) != 0) {
    const std::string e = std::strerror(errno);
    close_listener();
    throw std::runtime_error("device emulator: cannot listen on " + cfg_.socket_path + ": " + e);
  }
}

void DeviceEmulator::close_listener() {
  if (listen_fd_ < 0) return;
  ::close(listen_fd_);
  listen_fd_ = -1;
  ::unlink(cfg_.socket_path.c_str());
}

void DeviceEmulator::close_host() {
  if (host_fd_ >= 0) ::close(host_fd_);
  host_fd_ = -1;
  enabled_ = false;
  force_n_ = {};
}

void DeviceEmulator::accept_host() {
  if (host_fd_ >= 0 || listen_fd_ < 0) return;
  const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
  if (fd < 0) return;
  host_fd_ = fd;
  last_output_ns_ = now_ns();
  connected_at_s_ = clock_s_;  // the hand's path starts with each connection
  if (first_connected_at_s_ < 0) first_connected_at_s_ = clock_s_;
  std::lock_guard lock(stats_mu_);
  ++stats_.connections;
}

void DeviceEmulator::transmit(const std::uint8_t* b, std::size_t n) {
  if (host_fd_ < 0) return;
  if (::send(host_fd_, b, n, MSG_NOSIGNAL | MSG_DONTWAIT) < 0 && errno != EAGAIN) close_host();  // host gone
}

bool DeviceEmulator::chance(double p) {
  return p > 0 && std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < p;
}

Vec3 DeviceEmulator::hand_target(double t) const {
  if (cfg_.path.empty()) {
    const double s = cfg_.sine_amplitude_m * std::sin(2 * M_PI * cfg_.sine_hz * t);
    return cfg_.hold_m + Vec3{0, 0, s};
  }
  const double span = cfg_.path.back().t_s - cfg_.path.front().t_s;
  if (span > 0) t = cfg_.path.front().t_s + std::fmod(t, span);
  const auto it = std::lower_bound(cfg_.path.begin(), cfg_.path.end(), t,
                                   [](const PathPoint& p, double v) { return p.t_s < v; });
  if (it == cfg_.path.begin()) return it->p_m;
  if (it == cfg_.path.end()) return cfg_.path.back().p_m;
  const PathPoint& a = *(it - 1);
  const double u = it->t_s > a.t_s ? (t - a.t_s) / (it->t_s - a.t_s) : 1.0;
  return a.p_m + (it->p_m - a.p_m) * u;
}

void DeviceEmulator::serve_host(std::int64_t now) {
  std::array<std::uint8_t, 256> b{};
  while (host_fd_ >= 0) {
    const ssize_t n = ::recv(host_fd_, b.data(), b.size(), MSG_DONTWAIT);
    if (n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR)) {
      close_host();  // the host went away
      return;
    }
    if (n < 0) return;
    if (n == 1 && b[0] == servo::hid::kFeatureId) {  // GET_FEATURE: the capabilities
      const auto caps = servo::hid::encode_caps(cfg_.caps);
      transmit(caps.data(), caps.size());
      continue;
    }
    if (cfg_.polhem) {
      polhem_output(now, std::span(b.data(), std::size_t(n)));
      continue;
    }
    servo::hid::OutputReport o;
    std::lock_guard lock(stats_mu_);
    if (!servo::hid::decode(std::span(b.data(), std::size_t(n)), o)) {
      ++stats_.outputs_refused;
      continue;
    }
    log_output(now, o.force_n, o.enable, o.answers);
    last_output_ns_ = now;
    watchdog_tripped_ = false;
    enabled_ = o.enable;
    force_n_ = o.enable ? o.force_n : Vec3{};
    if (o.enable) stats_.max_force_n = std::max(stats_.max_force_n, norm(o.force_n));
    std::int64_t& sent = sent_ns_[o.answers % kSentRing];
    if (sent > 0) {
      stats_.latency_us.push_back(double(now - sent) * 1e-3);
      sent = 0;  // the first answer only
    }
  }
}

void DeviceEmulator::log_output(std::int64_t now, const Vec3& force_n, bool enable, std::uint64_t answers) {
  ++stats_.outputs_received;  // stats_mu_ held
  stats_.last_enable = enable;
  stats_.last_force_n = norm(force_n);
  if (log_.empty()) return;
  log_[logged_ % log_.size()] = ReceivedOutput{now, force_n, enable, answers};
  if (++logged_ > log_.size()) ++stats_.outputs_unlogged;
}

std::array<std::int16_t, 6> DeviceEmulator::polhem_counts() const {
  namespace ph = servo::hid::polhem;
  // The counts the unit's own kinematics give here, relative to its calibration pose, plus
  // what the counters read there: the calibration's counts, or the power-up error.
  const auto here = ph::encoders_for(dev_.position(), cfg_.polhem_config);
  const auto home = ph::calibration_counts(cfg_.polhem_config);
  std::array<std::int16_t, 6> e{};
  if (cfg_.polhem_power_up && !polhem_calibrated_) {  // counted from 0 where it powered up; d-f 0
    for (std::size_t i = 0; i < 3; ++i)
      e[i] = std::int16_t(std::clamp(long(here[i]) - polhem_power_up_counts_[i], -32768L, 32767L));
    return e;
  }
  for (std::size_t i = 0; i < 6; ++i) {
    const long moved = i < 3 ? long(here[i]) - home[i] : 0;  // d-f: no gimbal, it stays where calibrated
    const long at_home = polhem_calibrated_ ? polhem_set_[i] : i < 3 ? long(home[i]) + cfg_.polhem_offset_counts : 0;
    e[i] = std::int16_t(std::clamp(moved + at_home, -32768L, 32767L));
  }
  return e;
}

void DeviceEmulator::polhem_output(std::int64_t now, std::span<const std::uint8_t> b) {
  namespace ph = servo::hid::polhem;
  if (b.size() == ph::kReportSize + 1 && b[0] == 0) b = b.subspan(1);  // hidapi's leading report ID 0
  std::lock_guard lock(stats_mu_);
  if (b.size() != ph::kReportSize) {
    ++stats_.outputs_refused;
    return;
  }
  std::array<std::int16_t, 6> set{};
  if (ph::decode_calibrate(b, set)) {  // command 1, set the encoder counters: calibration
    ++stats_.calibrations;
    if (stats_.calibrations <= cfg_.polhem_lose_calibrations) {
      ++stats_.calibrations_lost;  // overwritten before the firmware read it: no answer either
      return;
    }
    if (!polhem_calibrated_) stats_.calibrated_ns = now;
    polhem_calibrated_ = true;
    polhem_flag_ = false;  // only the command clears it
    polhem_set_ = set;
    // The firmware's loop: no current this period (f[] stays 0), the watchdog re-armed.
    force_n_ = {}, enabled_ = false, last_output_ns_ = now, watchdog_tripped_ = false;
    polhem_owed_ = true;
    return;
  }
  Vec3 amps;
  if (!ph::decode_currents(b, amps)) {
    ++stats_.outputs_refused;
    return;
  }
  // The firmware applies the currents; the force they make at the true pose.
  const Vec3 f = ph::force_from_currents(amps, ph::encoders_for(dev_.position(), cfg_.polhem_config), cfg_.polhem_config);
  const bool on = norm(amps) > 0;
  log_output(now, f, on, 0);
  last_output_ns_ = now;
  watchdog_tripped_ = false;
  enabled_ = on;
  force_n_ = f;
  if (on) stats_.max_force_n = std::max(stats_.max_force_n, norm(f));
  if (on && !polhem_calibrated_) ++stats_.currents_while_uncalibrated;
  if (polhem_report_ns_ > 0) stats_.latency_us.push_back(double(now - polhem_report_ns_) * 1e-3);
  polhem_report_ns_ = 0;  // the first command after a report answers it
  polhem_owed_ = true;  // lock-step: this command is answered by one report
}

void DeviceEmulator::polhem_report(std::int64_t now) {
  if (!polhem_owed_) return;
  polhem_owed_ = false;
  polhem_report_ns_ = now;
  servo::hid::polhem::Input in;
  in.encoder = polhem_counts();
  in.info = polhem_flag_ ? 1 : 0;
  const auto bytes = servo::hid::polhem::encode(in);
  transmit(bytes.data(), bytes.size());
  std::lock_guard lock(stats_mu_);
  ++stats_.reports_sent;
}

void DeviceEmulator::send_report(std::int64_t now, double t_s) {
  if (cfg_.polhem) return polhem_report(now);
  servo::hid::InputReport r;
  r.sequence = ++seq_;
  r.device_time_us = std::uint32_t(std::int64_t(t_s * 1e6));
  r.position_m = dev_.position();
  r.flags = (enabled_ ? servo::hid::kForceEnabled : 0) | (watchdog_tripped_ ? servo::hid::kWatchdog : 0);
  auto bytes = servo::hid::encode(r);
  const EmuFaults& f = cfg_.faults;
  std::lock_guard lock(stats_mu_);
  if (chance(f.drop)) {
    ++stats_.dropped;
    return;
  }
  if (chance(f.garbage)) {
    for (auto& x : bytes) x = std::uint8_t(rng_());
    ++stats_.garbled;
  } else {
    sent_ns_[r.sequence % kSentRing] = now;
  }
  if (chance(f.delay)) {
    pending_.push_back({now + std::int64_t(f.delay_ms * 1e6), bytes});
    ++stats_.delayed;
    return;
  }
  if (hold_next_) {  // the held report goes after this one: reordered
    transmit(bytes.data(), bytes.size());
    transmit(held_.bytes.data(), held_.bytes.size());
    hold_next_ = false;
    ++stats_.reports_sent;
    return;
  }
  if (chance(f.reorder)) {
    held_ = {now, bytes};
    hold_next_ = true;
    ++stats_.reordered;
    return;
  }
  transmit(bytes.data(), bytes.size());
  ++stats_.reports_sent;
  if (chance(f.duplicate)) {
    transmit(bytes.data(), bytes.size());
    ++stats_.duplicated;
  }
}

double DeviceEmulator::fault_time_s(double t_s) const {
  if (!cfg_.faults.from_first_connection) return t_s;
  return first_connected_at_s_ < 0 ? -1.0 : t_s - first_connected_at_s_;  // -1: before every fault
}

void DeviceEmulator::tick(std::int64_t now, double t_s) {
  const EmuFaults& f = cfg_.faults;
  const double ft = fault_time_s(t_s);
  if (f.disconnect_at_s >= 0 && ft >= f.disconnect_at_s && !disconnected_) {
    disconnected_ = true;
    close_host();
    close_listener();
    std::lock_guard lock(stats_mu_);
    stats_.disconnect_ns = now_ns();
  }
  if (disconnected_ && !relistened_ && f.reconnect_after_s >= 0 && ft >= f.disconnect_at_s + f.reconnect_after_s) {
    relistened_ = true;
    listen();
  }
  // The handle pressed into the calibration switch: the firmware latches the edge (info 1
  // until a calibration command), whether or not a host is connected.
  if (cfg_.polhem && cfg_.polhem_power_up && cfg_.polhem_switch_at_s >= 0 && !polhem_pressed_ &&
      t_s >= cfg_.polhem_switch_at_s) {
    polhem_pressed_ = polhem_flag_ = true;
    std::lock_guard lock(stats_mu_);
    ++stats_.switch_presses;
  }
  accept_host();
  serve_host(now);
  // The device's own watchdog: no output report for the caps' watchdog time -> no force.
  if (cfg_.caps.watchdog_s > 0 && enabled_ && now - last_output_ns_ > std::int64_t(cfg_.caps.watchdog_s * 1e9)) {
    enabled_ = false, force_n_ = {}, watchdog_tripped_ = true;
    std::lock_guard lock(stats_mu_);
    ++stats_.watchdog_trips;
    if (stats_.first_watchdog_ns == 0) stats_.first_watchdog_ns = now;
  }
  const double T = 1.0 / cfg_.rate_hz;
  dev_.command_force(force_n_);
  clock_s_ = t_s;
  const double tp = t_s - connected_at_s_;
  const Vec3 a = hand_target(tp + T), b = hand_target(tp);
  dev_.step(T, a, (a - b) / T);
  const bool frozen = f.freeze_at_s >= 0 && ft >= f.freeze_at_s && ft < f.freeze_at_s + f.freeze_for_s;
  if (host_fd_ >= 0 && !frozen) send_report(now, t_s);
  for (auto it = pending_.begin(); it != pending_.end();) {  // delayed reports that are due
    if (it->due_ns <= now) {
      transmit(it->bytes.data(), it->bytes.size());
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
}

void DeviceEmulator::wait_until(std::int64_t t) {
  // Output reports are taken (and timestamped) as they arrive, not at the next tick: the
  // measured report-to-force latency is the host's, not this clock's phase.
  for (std::int64_t now = now_ns(); now < t; now = now_ns()) {
    if (host_fd_ < 0) {
      sleep_until(t);
      return;
    }
    pollfd p{host_fd_, POLLIN, 0};
    const std::int64_t left = t - now;
    const timespec ts{time_t(left / 1000000000LL), long(left % 1000000000LL)};
    if (::ppoll(&p, 1, &ts, nullptr) > 0) serve_host(now_ns());
  }
}

EmuStats DeviceEmulator::run() {
  listen();
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  // SCHED_FIFO where allowed, not pinned; refused: runs anyway at the default scheduler.
  if (cfg_.fifo_priority > 0) servo::make_thread_realtime("device emulator", true, cfg_.fifo_priority, false, -1);
  const auto period = std::int64_t(1e9 / cfg_.rate_hz + 0.5);
  const std::int64_t start = now_ns();
  {
    std::lock_guard lock(stats_mu_);
    stats_.start_ns = start;
  }
  std::int64_t next = start;
  for (long k = 0; !stop_.load(); ++k) {
    const double t_s = double(k) / cfg_.rate_hz;
    if (cfg_.seconds > 0 && t_s >= cfg_.seconds) break;
    next += period;
    wait_until(next);
    const std::int64_t now = now_ns();
    if (now - next > 10 * period) next = now;  // fell far behind (a stopped process): re-anchor
    tick(now, t_s);
  }
  close_host();
  close_listener();
  return stats();
}

EmuStats DeviceEmulator::stats() const {
  std::lock_guard lock(stats_mu_);
  return stats_;
}

std::vector<ReceivedOutput> DeviceEmulator::output_log() const {
  std::lock_guard lock(stats_mu_);
  const std::size_t n = std::min(logged_, log_.size());
  std::vector<ReceivedOutput> out;
  out.reserve(n);
  for (std::size_t i = logged_ - n; i < logged_; ++i) out.push_back(log_[i % log_.size()]);
  return out;
}

std::vector<PathPoint> load_path_csv(const std::string& path) {
  std::vector<PathPoint> out;
  for (const TimedPoint& r : load_timed_points(path, "the hand path", "t_s,x_m,y_m,z_m")) {
    PathPoint p;
    p.t_s = r.t_s;
    p.p_m = r.p_m;
    out.push_back(p);
  }
  return out;
}

}  // namespace isotouch::sim
