#include "isotouch/bench/bench_device.h"
#include "isotouch/io/files.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/bench/servo_bench.h"
#include "isotouch/sim/device_emulator.h"
#include "isotouch/run/sdk_haptic_device.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/forcedimension_device.h"
#include "isotouch/servo/openhaptics_device.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/servo_thread.h"
#include "isotouch/servo/socket_link.h"
#include "isotouch/service/igtl_device.h"
#include "isotouch/service/igtl_message.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/plus_peer.h"
#include "isotouch/service/stream_host.h"
#include "isotouch/eval/stats.h"

namespace isotouch::bench {
namespace {
using core::Vec3;

/// A wall at device z = 0 (inside below), 500 N/m: the emulator's hand holds the HIP in
/// it, so every tick renders a force (the figures are the link's, not the renderer's).
class Wall final : public servo::Renderer {
 public:
  const char* name() const override { return "wall"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView&, const Vec3& hip, double) override {
    servo::HriTick t;
    if (hip.z < 0) t.force_n = {0, 0, -500.0 * hip.z};
    return t;
  }
};

/// The wall, except that one tick in contact after `after_ticks` ticks takes `stall_ms`
/// (a slow renderer). Records when it stalled and went on (CLOCK_MONOTONIC [ns]).
class StallingWall final : public servo::Renderer {
 public:
  explicit StallingWall(int stall_ms) : stall_ms_(stall_ms) {}
  const char* name() const override { return "stalling wall"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView& f, const Vec3& hip, double dt) override {
    if (++ticks_ > kAfterTicks && hip.z < -0.0005 && start_ns == 0) {
      start_ns = steady_ns();
      std::this_thread::sleep_for(std::chrono::milliseconds(stall_ms_));
      end_ns = steady_ns();
    }
    return wall_.tick(f, hip, dt);
  }
  std::atomic<std::int64_t> start_ns{0}, end_ns{0};

 private:
  static std::int64_t steady_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  static constexpr long kAfterTicks = 150;
  int stall_ms_;
  long ticks_ = 0;
  Wall wall_;
};

/// Each tick's start and sent |F| (preallocated; read after the servo stopped).
struct TickLog final : servo::TickObserver {
  std::vector<std::int64_t> t_ns;
  std::vector<double> force;
  std::atomic<std::size_t> n{0};
  explicit TickLog(std::size_t max) : t_ns(max), force(max) {}
  void on_tick(const servo::TickRecord& r) noexcept override {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i >= t_ns.size()) return;
    t_ns[i] = r.t_ns, force[i] = core::norm(r.force_sent_n);
    n.store(i + 1, std::memory_order_release);
  }
};

struct EmuRun {
  sim::EmuStats emu;
  std::vector<sim::ReceivedOutput> wire;  // what the emulator received
  servo::LinkCounters link;
  servo::DeviceCounters dev;
  long ticks = 0, missed = 0;
  double seconds = 0;
  std::string setup_note;
};

/// The emulator at `rate_hz` for `seconds` (faults as given) against a servo at the same
/// rate rendering `renderer` (null: the wall); `polhem`: speaking the Polhem's reports
/// (lock-step: each currents command answered by one report) instead of protocol v1.
EmuRun run_against_emulator(double rate_hz, double seconds, const sim::EmuFaults& faults, bool fifo, TickLog* log,
                            servo::Renderer* renderer = nullptr, bool polhem = false) {
  sim::EmuConfig c;
  c.polhem = polhem;
  c.socket_path = "/tmp/isotouch-bench-device-" + std::to_string(::getpid()) + ".sock";
  c.rate_hz = rate_hz;
  c.seconds = seconds;
  c.hold_m = Vec3{0, 0, -0.003};
  c.caps.name = "bench-emu";
  c.caps.max_force_n = 10;
  c.caps.native_rate_hz = rate_hz;
  c.caps.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
  c.caps.workspace_max_m = Vec3{0.1, 0.1, 0.1};
  c.caps.watchdog_s = 0.05;
  c.faults = faults;
  c.fifo_priority = fifo ? 75 : 0;
  sim::DeviceEmulator emu(c);
  emu.listen();
  EmuRun out;
  std::thread emu_thread([&] { out.emu = emu.run(); });
  servo::ReportDeviceOptions ro;
  ro.fifo_priority = fifo ? 70 : 0;
  std::unique_ptr<servo::DeviceProtocol> protocol;
  if (polhem) protocol = std::make_unique<servo::PolhemProtocol>(c.polhem_config);
  else protocol = std::make_unique<servo::V1Protocol>();
  servo::ReportDevice dev(std::make_unique<servo::SocketLink>(c.socket_path), std::move(protocol), ro);
  try {
    dev.open();
  } catch (...) {
    emu.stop();
    emu_thread.join();
    throw;
  }
  servo::TripleBuffer<core::SampleField> published;
  published.publish(std::make_shared<const core::SampleField>(sim::plane_field({0, 0, 1}, {0.016, 0.016, 0.016})));
  Wall wall;
  servo::ServoThreadConfig sc;
  sc.rate_hz = rate_hz;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = fifo;
  sc.observer = log;
  servo::ServoThread servo(published, renderer ? *renderer : wall, dev, sc);
  const auto t0 = std::chrono::steady_clock::now();
  out.setup_note = servo.start() + dev.realtime_note();
  emu_thread.join();
  servo.stop();
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  out.ticks = servo.ticks();
  out.missed = servo.missed_deadlines();
  out.dev = servo.device_counters();
  out.wire = emu.output_log();
  dev.close();
  out.link = dev.counters();
  return out;
}

BenchDeviceRow measure_rate(double rate_hz, double seconds, bool fifo, std::string& note, bool polhem = false) {
  const EmuRun r = run_against_emulator(rate_hz, seconds, {}, fifo, nullptr, nullptr, polhem);
  if (note.empty()) note = r.setup_note;
  BenchDeviceRow row;
  row.rate_hz = rate_hz;
  row.seconds = r.seconds;
  row.report_rate_hz = double(r.link.reports) / seconds;
  row.answered = long(r.emu.latency_us.size());
  if (!r.emu.latency_us.empty()) {
    row.p50_us = eval::percentile(r.emu.latency_us, 0.5);
    row.p99_us = eval::percentile(r.emu.latency_us, 0.99);
    row.max_us = *std::max_element(r.emu.latency_us.begin(), r.emu.latency_us.end());
  }
  row.ticks = r.ticks, row.missed = r.missed, row.stale = r.dev.stale;
  return row;
}

DisconnectTrial disconnect_trial(bool fifo, std::uint32_t seed) {
  sim::EmuFaults f;
  f.disconnect_at_s = 0.15;
  f.seed = seed;
  TickLog log(4096);
  const EmuRun r = run_against_emulator(1000, 0.25, f, fifo, &log);
  DisconnectTrial t;
  const std::int64_t at = r.emu.disconnect_ns;
  t.zero_after_us = NAN;
  for (std::size_t i = 0; i < log.n.load(); ++i) {
    if (log.t_ns[i] <= at) continue;
    if (log.force[i] > 0) ++t.forced_ticks_after;
    else if (std::isnan(t.zero_after_us)) t.zero_after_us = double(log.t_ns[i] - at) * 1e-3;
  }
  return t;
}

StallTrial stall_trial(bool fifo) {
  StallingWall slow(100);
  const EmuRun r = run_against_emulator(1000, 0.5, {}, fifo, nullptr, &slow);
  StallTrial t;
  t.zero_after_us = t.resumed_n = NAN;
  t.watchdog_trips = r.emu.watchdog_trips;
  const std::int64_t from = slow.start_ns.load(), to = slow.end_ns.load();
  if (from == 0) return t;  // never stalled: the trial failed
  std::int64_t last_force = 0, zero = 0;  // the last force before the host's zero, and that zero
  for (const sim::ReceivedOutput& o : r.wire) {
    const bool forced = o.enable && core::norm(o.force_n) > 0;
    if (zero == 0) {
      if (forced) last_force = o.t_ns;
      else if (!o.enable && o.t_ns >= from) zero = o.t_ns;
    } else if (o.t_ns < to) {
      t.forced_during += forced;
    } else if (o.enable && std::isnan(t.resumed_n)) {
      t.resumed_n = core::norm(o.force_n);
    }
  }
  if (zero > 0) t.zero_after_us = double(zero - last_force) * 1e-3;
  return t;
}

std::string fixed(double v, int digits = 1) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

/// The servo at 1 kHz on the wall against a vendor SDK device (open) for `seconds`; the
/// latency is the device's own (SdkDevice::latencies_us(): from publishing a pose on the SDK's
/// thread to handing the force that answers it to the SDK), read after close.
BenchDeviceRow measure_sdk(servo::SdkDevice& dev, double seconds, bool fifo) {
  servo::TripleBuffer<core::SampleField> published;
  published.publish(std::make_shared<const core::SampleField>(sim::plane_field({0, 0, 1}, {0.016, 0.016, 0.016})));
  Wall wall;
  servo::ServoThreadConfig sc;
  sc.rate_hz = 1000;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = fifo;
  servo::ServoThread servo(published, wall, dev, sc);
  const auto t0 = std::chrono::steady_clock::now();
  servo.start();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  servo.stop();
  BenchDeviceRow row;
  row.rate_hz = 1000;
  row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  row.ticks = servo.ticks(), row.missed = servo.missed_deadlines(), row.stale = servo.device_counters().stale;
  row.report_rate_hz = double(dev.read().sequence) / row.seconds;
  return row;
}

void latency_figures(const std::vector<double>& us, BenchDeviceRow& row) {
  row.answered = long(us.size());
  if (us.empty()) return;
  row.p50_us = eval::percentile(us, 0.5);
  row.p99_us = eval::percentile(us, 0.99);
  row.max_us = *std::max_element(us.begin(), us.end());
}

/// One vendor SDK's row: "| openhaptics ... |", or why it was not measured.
std::string sdk_row(const char* kind, double seconds, bool fifo) {
  std::unique_ptr<servo::SdkDevice> dev;
  std::string what;
  try {
    dev = run::open_sdk_device(kind, "", what);
  } catch (const std::exception& e) {
    return std::string("| ") + kind + " | not measured: " + e.what() + " |\n";
  }
  BenchDeviceRow r = measure_sdk(*dev, seconds, fifo);
  dev->close();  // its device thread is done: the latencies may be read
  latency_figures(dev->latencies_us(), r);
  return "| " + what + " | " + fixed(r.report_rate_hz) + " | " + std::to_string(r.answered) + " | " + fixed(r.p50_us) +
         " | " + fixed(r.p99_us) + " | " + fixed(r.max_us) + " | " + std::to_string(r.ticks) + " | " +
         std::to_string(r.missed) + " | " + std::to_string(r.stale) + " |\n";
}
/// 0 N for `quiet_ticks`, then `force` along device x; once (at `stall_at` > 0 ticks) a tick
/// takes `stall_ms`.
class Push final : public servo::Renderer {
 public:
  Push(double force, long quiet_ticks, long stall_at, int stall_ms)
      : force_(force), quiet_(quiet_ticks), stall_at_(stall_at), stall_ms_(stall_ms) {}
  std::atomic<double> stall_from_s{0};  ///< when the stall began [s, CLOCK_MONOTONIC]
  const char* name() const override { return "push"; }
  void reset() override {}
  servo::HriTick tick(const core::FieldView&, const Vec3&, double) override {
    ++ticks_;
    if (ticks_ == stall_at_) {
      stall_from_s = std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
      std::this_thread::sleep_for(std::chrono::milliseconds(stall_ms_));
    }
    servo::HriTick t;
    if (ticks_ > quiet_) t.force_n = {force_, 0, 0};
    return t;
  }

 private:
  double force_;
  long quiet_, stall_at_;
  int stall_ms_;
  long ticks_ = 0;
};

using Rows = std::vector<std::array<double, 5>>;  // t_s, fx, fy, fz [N, the SDK's frame], flags

/// The servo at 1 kHz under a 3.3 N limit rendering `r` on `dev` for `seconds`; the gate's
/// rate limit it ran with [N/s].
double run_servo_on(servo::HapticDeviceIO& dev, servo::Renderer& r, double seconds, bool fifo, double stale_s = 0) {
  servo::TripleBuffer<core::SampleField> published;
  published.publish(std::make_shared<const core::SampleField>(sim::plane_field({0, 0, 1}, {0.016, 0.016, 0.016})));
  servo::ServoThreadConfig sc;
  sc.rate_hz = 1000;
  sc.force_limit_n = 3.3;
  sc.stale_timeout_s = stale_s;
  sc.sched_fifo = sc.pin_cpu = sc.lock_memory = fifo;
  servo::ServoThread servo(published, r, dev, sc);
  servo.start();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  servo.stop();
  return servo::force_limits(dev.caps(), sc.force_limit_n).rate_n_per_s;
}

/// `kind`'s device opened, the servo at 1 kHz (force limit 3.3 N) rendering `r` for `seconds`,
/// closed; what the library received (its double's log: dlsym; empty for a real SDK).
Rows sdk_run(const std::string& kind, servo::Renderer& r, double seconds, bool fifo, double& rate_limit,
             std::string& why_not) {
  std::unique_ptr<servo::SdkDevice> dev;
  try {
    std::string what;
    dev = run::open_sdk_device(kind, "", what);
  } catch (const std::exception& e) {
    why_not = e.what();
    return {};
  }
  using LogFn = int (*)(double*, int);
  const auto log = reinterpret_cast<LogFn>(dlsym(RTLD_DEFAULT, kind == "openhaptics" ? "hdDoubleLog" : "dhdDoubleLog"));
  using ClearFn = void (*)();
  const auto clear = reinterpret_cast<ClearFn>(dlsym(RTLD_DEFAULT, kind == "openhaptics" ? "hdDoubleClearLog" : "dhdDoubleClearLog"));
  if (!log || !clear) {
    dev->close();
    why_not = "the library does not log what the device received (a real SDK): not judged";
    return {};
  }
  clear();
  rate_limit = run_servo_on(*dev, r, seconds, fifo);
  dev->close();
  Rows rows(1 << 16);
  const int n = log(rows.front().data(), int(rows.size()));
  // The double's log counts from its start: CLOCK_MONOTONIC, as the renderer's stall time.
  using StartFn = double (*)();
  const auto start = reinterpret_cast<StartFn>(dlsym(RTLD_DEFAULT, kind == "openhaptics" ? "hdDoubleStartS" : "dhdDoubleStartS"));
  const double t0 = start ? start() : 0;
  for (int k = 0; k < std::min(n, int(rows.size())); ++k) rows[std::size_t(k)][0] += t0;
  rows.resize(std::size_t(std::clamp(n, 0, int(rows.size()))));
  return rows;
}

double row_norm(const std::array<double, 5>& r) { return std::sqrt(r[1] * r[1] + r[2] * r[2] + r[3] * r[3]); }

/// The stall (a 100 ms renderer tick while pushing 1 N) and the step (0 -> 3 N) on `kind`.
SdkTrial sdk_trial(const std::string& kind, bool fifo) {
  SdkTrial t;
  t.kind = kind;
  Push stalling(1.0, 50, 400, 100);
  const Rows stall = sdk_run(kind, stalling, 0.8, fifo, t.rate_limit_n_per_s, t.not_measured);
  if (!t.not_measured.empty()) return t;
  // The stall: the first run of zeros lasting 50 ms or more after the push began (a stale blip
  // of a tick or two on a busy machine is not it); the last force before it, the first after.
  std::size_t i = 0;
  while (i < stall.size() && row_norm(stall[i]) < 0.999) ++i;  // pushing 1 N
  for (; i + 1 < stall.size(); ++i) {
    if (!(row_norm(stall[i]) > 0 && row_norm(stall[i + 1]) == 0)) continue;
    std::size_t j = i + 1;
    while (j < stall.size() && row_norm(stall[j]) == 0) ++j;
    if (j < stall.size() && stall[j][0] - stall[i + 1][0] < 0.05) continue;  // a blip, not the stall
    t.steady_n = row_norm(stall[i]);
    // From the renderer's stall (the servo's last write came before it): the first zero the
    // library got; the device thread looks once a frame, so this is its own cadence too.
    t.stall_zero_after_us = (stall[i + 1][0] - stalling.stall_from_s.load()) * 1e6;
    if (j < stall.size()) t.stall_resumed_n = row_norm(stall[j]);
    break;
  }
  Push step(3.0, 200, 0, 0);
  std::string why;
  double rate = 0;
  const Rows rows = sdk_run(kind, step, 0.5, fifo, rate, why);
  std::size_t k = 0;
  while (k < rows.size() && row_norm(rows[k]) == 0) ++k;
  t.step_max_rate_n_per_s = t.step_bound_n_per_s = 0;
  const std::size_t first = k;
  for (k = std::max<std::size_t>(first, 1); k < rows.size(); ++k) {
    const double dt = rows[k][0] - rows[k - 1][0];
    if (!(dt > 0)) continue;
    const double df = std::sqrt(std::pow(rows[k][1] - rows[k - 1][1], 2) + std::pow(rows[k][2] - rows[k - 1][2], 2) +
                                std::pow(rows[k][3] - rows[k - 1][3], 2));
    if (df / dt > t.step_max_rate_n_per_s) {
      t.step_max_rate_n_per_s = df / dt;
      // Each servo write changes the force by at most rate x its period; a frame's interval
      // holds its own writes and, with a late tick and the next one on time, two more.
      t.step_bound_n_per_s = rate * (dt + 2e-3) / dt;
    }
    if (std::isnan(t.step_rise_ms) && row_norm(rows[k]) > 3.0 - 1e-9 && first < rows.size())
      t.step_rise_ms = (rows[k][0] - rows[first][0]) * 1e3;
  }
  return t;
}

/// What the PLUS-like peer got over a link run: the relay delay (a Force's arrival after the
/// newest pose it had sent), the step's rise held to the gate's rate, and the stall's zero.
void judge_link(const service::PlusPeer& peer, double rate_limit_n_per_s, double step_n, std::int64_t stall_from_ns,
                IgtlRow& row) {
  const std::vector<std::int64_t> sent = peer.poses_ns();
  const std::vector<service::PeerForce> got = peer.forces();
  row.forces = long(got.size());
  if (sent.size() > 1)
    row.stream_hz = double(sent.size() - 1) / (double(sent.back() - sent.front()) * 1e-9);
  std::vector<double> delay_us;
  for (const service::PeerForce& g : got) {
    const auto it = std::upper_bound(sent.begin(), sent.end(), g.t_ns);  // the newest pose sent before it
    if (it != sent.begin()) delay_us.push_back(double(g.t_ns - *(it - 1)) * 1e-3);
  }
  if (!delay_us.empty()) {
    row.p50_us = eval::percentile(delay_us, 0.5);
    row.p99_us = eval::percentile(delay_us, 0.99);
    row.max_us = *std::max_element(delay_us.begin(), delay_us.end());
  }
  // The step: from the first force after the quiet ticks to the first at the full step, each
  // change against the rate over the time since the row before plus one servo period (a
  // Force answers the newest pose: two servo writes may fall between two Forces).
  std::size_t i = 0;
  while (i < got.size() && core::norm(got[i].f) == 0) ++i;
  const std::size_t rise_from = i;
  row.step_rate_n_per_s = 0, row.step_allowed_n_per_s = rate_limit_n_per_s;
  while (i < got.size() && core::norm(got[i].f) < step_n - 1e-3) ++i;  // the first at the full step
  for (std::size_t k = std::max<std::size_t>(rise_from, 1); k < got.size() && k <= i; ++k) {
    const double dt = double(got[k].t_ns - got[k - 1].t_ns) * 1e-9;
    const double df = core::norm(got[k].f) - core::norm(got[k - 1].f);
    if (dt <= 0) continue;
    if (df / dt > row.step_rate_n_per_s)
      row.step_rate_n_per_s = df / dt, row.step_allowed_n_per_s = rate_limit_n_per_s * (dt + 1e-3) / dt;
  }
  if (i < got.size() && rise_from < got.size()) row.step_rise_ms = double(got[i].t_ns - got[rise_from].t_ns) * 1e-6;
  // The stall: from the renderer's stall (the servo's last write was before it) to the first
  // zero the peer got after it, as the SDK trials time it.
  for (const service::PeerForce& g : got)
    if (stall_from_ns > 0 && g.t_ns > stall_from_ns && core::norm(g.f) == 0) {
      row.stall_zero_after_us = double(g.t_ns - stall_from_ns) * 1e-3;
      break;
    }
}

/// A link on loopback against a PLUS-like peer (service/plus_peer.h) streaming poses at
/// 1 kHz: `--haptic igtl:` (the peer listens, isotouch connects) or serve's TRANSFORM stream
/// (`serve --reply-force`: the peer is its client; service/stream_host.h runs serve's reply
/// thread). The servo at 1 kHz under a 3.3 N limit: 50 quiet ticks, a step to 3 N, one 100 ms
/// renderer stall half-way.
IgtlRow link_row(const std::string& kind, double seconds, bool fifo) {
  IgtlRow row;
  row.kind = kind;
  const double step_n = 3.0;
  Push push(step_n, 50, long(seconds * 500), 100);
  service::PlusPeerOptions po;
  po.fifo_priority = fifo ? 60 : 0;  // a device loop's priority where allowed (PLUS's is)
  std::unique_ptr<service::PlusPeer> peer;
  double rate_limit = 0;
  try {
    if (kind == "igtl") {
      peer = std::make_unique<service::PlusPeer>(po);
      service::IgtlDeviceOptions opt;
      opt.host = "127.0.0.1";
      opt.port = peer->port();
      opt.measure_s = 0.3;
      opt.fifo_priority = fifo ? 70 : 0;  // as `run --live --haptic igtl:` with SCHED_FIFO
      service::IgtlDevice dev(opt);
      rate_limit = run_servo_on(dev, push, seconds, fifo);
    } else {
      // Stale after 3 of the stream's periods, as `--haptic igtl:` measures its own.
      service::StreamHost host(service::StreamReplyOptions{fifo, 3e-3});
      po.connect_host = "127.0.0.1", po.connect_port = host.port();
      peer = std::make_unique<service::PlusPeer>(po);
      rate_limit = run_servo_on(host.device(), push, seconds, fifo, 3e-3);
      host.stop();  // its last act: a zero
    }
  } catch (const std::exception& e) {
    row.not_measured = e.what();
    return row;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the last zero in flight
  peer->finish();
  judge_link(*peer, rate_limit, step_n, std::int64_t(push.stall_from_s.load() * 1e9), row);
  return row;
}

std::string sdk_trial_line(const SdkTrial& t) {
  if (!t.not_measured.empty()) return "  " + t.kind + ": not measured: " + t.not_measured + "\n";
  return "  " + t.kind + ": stall: zero " + fixed(t.stall_zero_after_us) + " us after the renderer stalled (pushing " +
         fixed(t.steady_n, 3) + " N), first force after it " + fixed(t.stall_resumed_n, 3) + " N; step 0 -> 3 N: largest |dF|/dt " +
         fixed(t.step_max_rate_n_per_s) + " N/s (allowed " + fixed(t.step_bound_n_per_s) + " over that frame, rate limit " +
         fixed(t.rate_limit_n_per_s) + " N/s), 3 N reached " + fixed(t.step_rise_ms, 2) + " ms after the first force\n";
}
}  // namespace

std::vector<std::string> bench_device_verdicts(const std::vector<BenchDeviceRow>& rows,
                                               const std::vector<DisconnectTrial>& trials,
                                               const std::vector<StallTrial>& stalls,
                                               const std::vector<SdkTrial>& sdk, const std::vector<IgtlRow>& links) {
  std::vector<std::string> v;
  const auto one = std::find_if(rows.begin(), rows.end(), [](const BenchDeviceRow& r) { return r.rate_hz == 1000; });
  if (one == rows.end() || one->answered == 0 || !std::isfinite(one->p99_us))
    v.push_back("p99 report-to-force at 1 kHz: not measured: target <= 1000 us NOT met");
  else
    v.push_back("p99 report-to-force at 1 kHz = " + fixed(one->p99_us) + " us: target <= 1000 us " +
                (one->p99_us <= 1000 ? "met" : "NOT met"));
  long good = 0;
  for (const DisconnectTrial& t : trials) good += t.forced_ticks_after <= 1 && std::isfinite(t.zero_after_us);
  v.push_back("zero force within one tick of a disconnect in " + std::to_string(good) + " of " +
              std::to_string(trials.size()) + " trials: " +
              (!trials.empty() && good == long(trials.size()) ? "met" : "NOT met"));
  // A stall at 1 kHz: zero with enable cleared within 3 periods (3000 us) of the last force,
  // no force during it, the force back from 0 (the ramp), the device's watchdog untouched.
  long ok = 0;
  double worst = 0;
  for (const StallTrial& t : stalls) {
    ok += t.zero_after_us <= 3000 && t.forced_during == 0 && t.resumed_n == 0 && t.watchdog_trips == 0;
    worst = std::isnan(t.zero_after_us) ? INFINITY : std::max(worst, t.zero_after_us);
  }
  v.push_back("zero force with enable cleared within 3 periods of a servo stall (none during it, back through the "
              "ramp) in " + std::to_string(ok) + " of " + std::to_string(stalls.size()) + " trials, worst " +
              fixed(worst) + " us: " + (!stalls.empty() && ok == long(stalls.size()) ? "met" : "NOT met"));
  // Each vendor SDK that logs what it received: the stall's zero within 3 periods of the
  // renderer's stall (the servo's last write was before it) and the force back from a ramp
  // (under a tenth of the steady force); the step's
  // change per frame within the gate's rate.
  for (const SdkTrial& t : sdk) {
    if (!t.not_measured.empty()) continue;
    const bool stall_ok = t.stall_zero_after_us <= 3000 && t.stall_resumed_n < 0.1 * t.steady_n;
    v.push_back(t.kind + ": zero within 3 periods of a servo stall (" + fixed(t.stall_zero_after_us) +
                " us after it began), back through the ramp (" + fixed(t.stall_resumed_n, 3) + " N first): " + (stall_ok ? "met" : "NOT met"));
    const bool step_ok = t.step_max_rate_n_per_s <= t.step_bound_n_per_s * (1 + 1e-9) && std::isfinite(t.step_rise_ms);
    v.push_back(t.kind + ": a 0 -> 3 N step held to the rate limit (largest " + fixed(t.step_max_rate_n_per_s) +
                " N/s against " + fixed(t.step_bound_n_per_s) + "): " + (step_ok ? "met" : "NOT met"));
  }
  // Each link, over its trials: the stall's zero reaches the peer within 3 servo periods of
  // the stall; the step's rise at the peer within the gate's rate.
  std::vector<std::string> kinds;
  for (const IgtlRow& l : links)
    if (std::find(kinds.begin(), kinds.end(), l.kind) == kinds.end()) kinds.push_back(l.kind);
  for (const std::string& kind : kinds) {
    long n = 0, stall_ok = 0, step_ok = 0;
    double slowest = 0, steepest = 0, allowed = NAN;
    for (const IgtlRow& l : links) {
      if (l.kind != kind) continue;
      ++n;
      const bool measured = l.not_measured.empty();
      stall_ok += measured && l.stall_zero_after_us <= 3000;
      slowest = measured && std::isfinite(l.stall_zero_after_us) ? std::max(slowest, l.stall_zero_after_us) : INFINITY;
      step_ok += measured && l.step_rate_n_per_s <= l.step_allowed_n_per_s * (1 + 1e-9) && std::isfinite(l.step_rise_ms);
      if (measured && l.step_rate_n_per_s > steepest) steepest = l.step_rate_n_per_s, allowed = l.step_allowed_n_per_s;
    }
    v.push_back(kind + ": zero at the peer within 3 periods of a servo stall in " + std::to_string(stall_ok) + " of " +
                std::to_string(n) + " trials, worst " + fixed(slowest) + " us after it began: " +
                (n > 0 && stall_ok == n ? "met" : "NOT met"));
    v.push_back(kind + ": a 0 -> 3 N step held to the rate limit at the peer in " + std::to_string(step_ok) + " of " +
                std::to_string(n) + " trials (steepest " + fixed(steepest) + " N/s against " + fixed(allowed) +
                "): " + (n > 0 && step_ok == n ? "met" : "NOT met"));
  }
  return v;
}

int run_bench_device(const BenchDeviceOptions& o, std::ostream& log) {
  log << "bench device: report-to-force over isotouch-devemu's emulator (protocol v1, Unix-domain socket), "
      << o.seconds << " s per rate; " << cpu_model() << ", load " << load_average() << "\n";
  std::string note;
  std::vector<BenchDeviceRow> rows;
  for (double rate : {1000.0, 4000.0, 8000.0}) rows.push_back(measure_rate(rate, o.seconds, o.sched_fifo, note));
  if (!note.empty()) log << note;
  log << "\n| rate [Hz] | reports/s | answered | p50 [us] | p99 [us] | max [us] | servo ticks | missed | stale ticks |\n"
         "|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchDeviceRow& r : rows)
    log << "| " << r.rate_hz << " | " << fixed(r.report_rate_hz) << " | " << r.answered << " | " << fixed(r.p50_us)
        << " | " << fixed(r.p99_us) << " | " << fixed(r.max_us) << " | " << r.ticks << " | " << r.missed << " | "
        << r.stale << " |\n";
  {
    std::string polhem_note;
    const BenchDeviceRow p = measure_rate(1000, o.seconds, o.sched_fifo, polhem_note, true);
    log << "\nthe Polhem's reports over the same emulator (lock-step: a report answered by the next currents "
           "command; relay delay = that command's arrival after the report was sent), 1 kHz: "
        << fixed(p.report_rate_hz) << " reports/s, " << p.answered << " answered; relay delay p50 " << fixed(p.p50_us)
        << " us, p99 " << fixed(p.p99_us) << " us, max " << fixed(p.max_us) << " us; " << p.ticks << " servo ticks, "
        << p.missed << " missed, " << p.stale << " stale\n";
  }
  log << "\nvendor SDKs at 1 kHz (ISOTOUCH_HD_LIBRARY, ISOTOUCH_DHD_LIBRARY: the test doubles in "
         "build/tests/sdk_doubles or the SDKs; latency from the pose published on the SDK's thread to the force "
         "handed to the SDK):\n"
         "| device | poses/s | answered | p50 [us] | p99 [us] | max [us] | servo ticks | missed | stale ticks |\n"
         "|---|---|---|---|---|---|---|---|---|\n"
      << sdk_row("openhaptics", o.seconds, o.sched_fifo) << sdk_row("forcedimension", o.seconds, o.sched_fifo);
  std::vector<DisconnectTrial> trials;
  for (int i = 0; i < o.disconnect_trials; ++i) trials.push_back(disconnect_trial(o.sched_fifo, std::uint32_t(i + 1)));
  log << "\ndisconnect trials at 1 kHz (the emulator closes the link while the servo renders ~0.56 N):\n";
  for (std::size_t i = 0; i < trials.size(); ++i)
    log << "  trial " << i + 1 << ": " << trials[i].forced_ticks_after << " ticks forced after it, first zero-force tick "
        << fixed(trials[i].zero_after_us) << " us after it\n";
  std::vector<StallTrial> stalls;
  for (int i = 0; i < o.stall_trials; ++i) stalls.push_back(stall_trial(o.sched_fifo));
  log << "\nstall trials at 1 kHz (the renderer takes 100 ms once while the device is pushed, ~0.56 N):\n";
  for (std::size_t i = 0; i < stalls.size(); ++i)
    log << "  trial " << i + 1 << ": zero with enable cleared " << fixed(stalls[i].zero_after_us)
        << " us after the last force, " << stalls[i].forced_during << " forced outputs during the stall, first force after it "
        << fixed(stalls[i].resumed_n, 3) << " N, " << stalls[i].watchdog_trips << " watchdog trips\n";
  std::vector<SdkTrial> sdk;
  for (const char* kind : {"openhaptics", "forcedimension"}) sdk.push_back(sdk_trial(kind, o.sched_fifo));
  log << "\nvendor SDK trials at 1 kHz (a 100 ms renderer stall while pushing 1 N; a 0 -> 3 N step under a 3.3 N "
         "limit), judged on what the library received:\n";
  for (const SdkTrial& t : sdk) log << sdk_trial_line(t);
  std::vector<IgtlRow> links;
  for (const char* kind : {"igtl", "serve stream"})
    for (int i = 0; i < o.stall_trials; ++i) links.push_back(link_row(kind, std::min(o.seconds, 2.0), o.sched_fifo));
  log << "\nlinks on loopback (a PLUS-like peer in this process streaming poses at 1 kHz: `--haptic igtl:` connects to "
         "it, serve's TRANSFORM stream answers it; the servo at 1 kHz under 3.3 N: a 0 -> 3 N step, one 100 ms renderer "
         "stall; relay delay = a Force's arrival at the peer after the newest pose it had sent), "
      << o.stall_trials << " trials each:\n";
  for (const IgtlRow& l : links) {
    if (!l.not_measured.empty()) {
      log << "  " << l.kind << ": not measured: " << l.not_measured << "\n";
      continue;
    }
    log << "  " << l.kind << ": stream " << fixed(l.stream_hz) << " Hz, " << l.forces << " forces; relay delay p50 "
        << fixed(l.p50_us) << " us, p99 " << fixed(l.p99_us) << " us, max " << fixed(l.max_us) << " us; step: largest dF/dt "
        << fixed(l.step_rate_n_per_s) << " N/s (allowed " << fixed(l.step_allowed_n_per_s) << "), 3 N "
        << fixed(l.step_rise_ms, 2) << " ms after the first force; the stall's zero " << fixed(l.stall_zero_after_us)
        << " us after it began\n";
  }
  log << "\n";
  for (const std::string& v : bench_device_verdicts(rows, trials, stalls, sdk, links)) log << "verdict  " << v << "\n";
  if (!o.out_csv.empty()) {
    std::ostringstream csv;
    csv << "rate_hz,report_rate_hz,answered,p50_us,p99_us,max_us,ticks,missed,stale\n";
    for (const BenchDeviceRow& r : rows)
      csv << r.rate_hz << ',' << r.report_rate_hz << ',' << r.answered << ',' << r.p50_us << ',' << r.p99_us << ','
          << r.max_us << ',' << r.ticks << ',' << r.missed << ',' << r.stale << '\n';
    io::write_file_atomic(o.out_csv, csv.str());  // whole or not at all
  }
  return std::all_of(rows.begin(), rows.end(), [](const BenchDeviceRow& r) { return r.answered == 0; }) ? 1 : 0;
}


}  // namespace isotouch::bench
