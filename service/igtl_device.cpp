#include "isotouch/service/igtl_device.h"

#include <pthread.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "isotouch/service/igtl_reply_rule.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/sim/stability.h"

namespace isotouch::service {
namespace {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string num(double v, int precision = 4) {
  std::ostringstream s;
  s.precision(precision);
  s << v;
  return s.str();
}

}  // namespace

IgtlDeviceOptions parse_igtl_spec(const std::string& arg) {
  IgtlDeviceOptions o;
  const std::size_t a = arg.find(':');
  const std::size_t b = a == std::string::npos ? a : arg.find(':', a + 1);
  o.host = arg.substr(0, a);
  const std::string port = a == std::string::npos ? "" : arg.substr(a + 1, b == std::string::npos ? b : b - a - 1);
  if (b != std::string::npos) o.stream = arg.substr(b + 1);
  std::size_t used = 0;
  int p = -1;
  try {
    p = std::stoi(port, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (o.host.empty()) throw std::invalid_argument("igtl:" + arg + ": no host (igtl:HOST:PORT[:STREAM])");
  if (used == 0 || used != port.size() || p < 1 || p > 65535)
    throw std::invalid_argument("igtl:" + arg + ": port '" + port + "' is not 1 to 65535 (igtl:HOST:PORT[:STREAM])");
  if (o.stream.empty() || o.stream.size() > 20)
    throw std::invalid_argument("igtl:" + arg + ": stream '" + o.stream + "' is not 1 to 20 characters (a device name)");
  o.port = p;
  return o;
}

IgtlDevice::IgtlDevice(const IgtlDeviceOptions& o) : o_(o) {
  conn_ = std::make_shared<Connection>(connect_tcp(o.host, o.port, o.connect_timeout_ms), o.receive_timeout_ms,
                                       o.receive_timeout_ms, &stop_);
  reader_ = std::thread([this] { read_loop(); });
  try {
    measure(o.measure_s);
  } catch (...) {
    stop_ = true;
    conn_->shutdown();
    reader_.join();
    throw;
  }
  const double zero[3] = {0, 0, 0};
  const std::vector<std::uint8_t> z = pack_translation("Force", zero);
  exit_zero_ = std::make_unique<ExitZeroFence>(conn_->fd(), z);
  conn_->set_fence(exit_zero_.get());
  rule_.restart(now_ns());
  writer_ = std::thread([this] { write_loop(); });
}

IgtlDevice::~IgtlDevice() {
  stop_ = true;
  if (writer_.joinable()) writer_.join();  // its last act: a zero force
  conn_->set_fence(nullptr);
  exit_zero_.reset();
  conn_->shutdown();
  if (reader_.joinable()) reader_.join();
}

/// Waits `seconds` and takes the stream's rate from the poses that arrived.
void IgtlDevice::measure(double seconds) {
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const long n = poses_.load();
  const double span_s = double(last_ns_.load() - first_ns_.load()) * 1e-9;
  if (n < 10 || !(span_s > 0)) {
    throw std::runtime_error("igtl:" + o_.host + ":" + std::to_string(o_.port) + ": " + std::to_string(n) +
                             " TRANSFORMs named '" + o_.stream + "' in " + num(seconds) + " s (" +
                             std::to_string(others_.load()) + " other messages" +
                             (closed_ ? ", then the connection closed" : "") + "); at least 10 are needed to measure the rate");
  }
  rate_hz_ = double(n - 1) / span_s;
}

void block_stop_signals() {
  sigset_t s;
  sigemptyset(&s);
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) sigaddset(&s, sig);
  pthread_sigmask(SIG_BLOCK, &s, nullptr);
}

void IgtlDevice::read_loop() {
  block_stop_signals();
  servo::ensure_signal_stack();  // a stack overflow here still sends the peer its zero
  for (;;) {
    Incoming in = read_message(*conn_, MessageLimits{});
    if (in.kind == Incoming::Kind::kClosed || in.kind == Incoming::Kind::kBroken) break;
    if (in.kind != Incoming::Kind::kTransform || in.device != o_.stream) {
      others_.fetch_add(1);
      continue;
    }
    Pose p = pose_.load();
    p.m = {in.matrix[0][3] * 1e-3, in.matrix[1][3] * 1e-3, in.matrix[2][3] * 1e-3};
    p.received_ns = now_ns();
    ++p.sequence;
    pose_.store(p);
    if (poses_.fetch_add(1) == 0) first_ns_ = p.received_ns;
    last_ns_ = p.received_ns;
  }
  closed_ = true;
}

servo::DeviceReading IgtlDevice::read() {
  pose_.load(last_);
  servo::DeviceReading r;
  r.position_m = last_.m;
  r.received_ns = last_.received_ns > 0 ? last_.received_ns : 1;  // nothing yet: stale
  r.sequence = last_.sequence;
  if (closed_.load(std::memory_order_relaxed)) r.status = servo::DeviceStatus::kDisconnected;
  return r;
}

void IgtlDevice::write_force_n(const core::Vec3& f) {
  rule_.write(f, last_.sequence, now_ns());  // non-finite: zero; the first write after a stall: zero
}

servo::DeviceCaps IgtlDevice::caps() const {
  servo::DeviceCaps c;
  c.name = "OpenIGTLink '" + o_.stream + "'";
  c.native_rate_hz = rate_hz_;
  c.stale_timeout_s = 3.0 / rate_hz_;
  c.max_force_n = o_.max_force_n;  // the peer's device, as the scene declares it
  return c;
}

const std::atomic<std::uint64_t>* IgtlDevice::enable_force(bool on, double stall_s) {
  return rule_.enable(on, stall_s, 0.05, now_ns());  // the writer polls: no look period to allow for
}

void IgtlDevice::send_force(const core::Vec3& f) {
  const double t[3] = {f.x, f.y, f.z};
  if (conn_->send(pack_translation("Force", t))) sent_.fetch_add(1);  // fenced (ExitZeroFence)
}

/// Polls every 0.2 ms (a fifth of the stall time when that is shorter: a stall is found within
/// stall time + a fifth of it; one poll more after this thread was itself frozen) and sends
/// what IgtlReplyRule says.
void IgtlDevice::write_loop() {
  block_stop_signals();
  servo::ensure_signal_stack();
  if (o_.fifo_priority > 0) servo::make_thread_realtime("igtl writer", true, o_.fifo_priority, false, -1);
  IgtlReplyRule reply(std::int64_t(3e9 / rate_hz_));
  while (!stop_) {
    const std::int64_t poll_ns = std::min<std::int64_t>(200'000, std::max<std::int64_t>(rule_.stall_ns() / 5, 10'000));
    std::this_thread::sleep_for(std::chrono::nanoseconds(poll_ns));
    const Pose p = pose_.load();
    const std::int64_t t = now_ns();  // the clock before the cell (StallRule::look)
    if (!reply.judge_now(t, 5 * poll_ns)) continue;  // this thread was frozen: look again in a poll
    const IgtlReply r = reply.step(p.sequence, p.received_ns, rule_.look(t), t);
    if (r.send) send_force(r.force_n);
  }
  send_force({0, 0, 0});
}

LinkStiffness judge_link_stiffness(const IgtlLoop& loop, double rate_hz) {
  LinkStiffness j;
  j.loop_hz = std::min(rate_hz, loop.servo_rate_hz);
  j.colgate_n_per_m = sim::colgate_k_max(loop.handle_damping_n_s_per_m, loop.servo_damping_n_s_per_m, 1.0 / j.loop_hz);
  sim::LinkedContact press;  // the link sweep's press, with the scene's device, hand and B
  press.device = loop.device;
  press.device.force_max_n = 1e3;  // as the sweep: what the link does, not the motor's limit
  press.servo_damping_n_s_per_m = loop.servo_damping_n_s_per_m;
  j.bound = sim::link_k_max(press, j.loop_hz, loop.round_trip_s);
  j.limit_n_per_m = loop.peer_passivity_control ? j.bound.k_max_with_pc_n_per_m : j.bound.k_max_n_per_m;
  j.over = loop.stiffness_n_per_m > j.limit_n_per_m;
  std::ostringstream s;
  s << "through the link (simulated: the scene's device and hand pressing a wall at " << num(j.loop_hz)
    << " Hz, each force held one period, round trip " << num(loop.round_trip_s * 1e3)
    << " ms beyond the hold, device.link_round_trip_ms: the stream cannot measure it) K_max "
    << num(j.bound.k_max_n_per_m) << " N/m without the passivity controller, " << num(j.bound.k_max_with_pc_n_per_m)
    << " N/m with it at the peer's end (device.link_passivity_control "
    << (loop.peer_passivity_control ? "true: the bound with it applies" : "false: the bound without it applies") << ")";
  j.text = s.str();
  return j;
}

std::unique_ptr<IgtlDevice> open_igtl_device(const std::string& arg, const IgtlLoop& loop, std::string& description,
                                             int fifo_priority, double max_force_n) {
  IgtlDeviceOptions o = parse_igtl_spec(arg);
  o.fifo_priority = fifo_priority;
  o.max_force_n = max_force_n;
  auto d = std::make_unique<IgtlDevice>(o);
  const double rate = d->measured_rate_hz();
  const LinkStiffness j = judge_link_stiffness(loop, rate);
  std::ostringstream s;
  s << "igtl:" << arg << " (" << d->caps().name << " at " << num(rate) << " Hz measured; the force loop closes at "
    << num(j.loop_hz) << " Hz: Colgate-Schenkel K <= 2 (b - |B|) / T = " << num(j.colgate_n_per_m) << " N/m with b "
    << loop.handle_damping_n_s_per_m << " N s/m, B " << loop.servo_damping_n_s_per_m << " N s/m; " << j.text
    << "; the scene's K " << loop.stiffness_n_per_m << " N/m; the peer's device is sent at most " << num(max_force_n)
    << " N, the scene's device.link_max_force_n)";
  description = s.str();
  if (j.over) {
    if (!loop.allow_unstable_stiffness) {
      const bool pc_would = !loop.peer_passivity_control && !(loop.stiffness_n_per_m > j.bound.k_max_with_pc_n_per_m);
      throw std::runtime_error(
          description + ": servo.stiffness_n_per_m " + num(loop.stiffness_n_per_m) + " is above the bound " +
          num(j.limit_n_per_m) + " N/m " + (loop.peer_passivity_control ? "with" : "without") +
          " the passivity controller at the peer's end (" + num(j.bound.k_max_n_per_m) + " N/m without it, " +
          num(j.bound.k_max_with_pc_n_per_m) + " N/m with it) at this rate and delay; the contact may buzz: lower the "
          "stiffness, raise the stream's rate, " +
          (pc_would ? std::string("run the passivity controller on the peer and say so (the scene's "
                                  "device.link_passivity_control: true), ")
                    : std::string()) +
          "or allow it (--allow-unstable-stiffness, or the scene's servo.allow_unstable_stiffness)");
    }
    description += "; warning: K is above the bound (allowed)";
  }
  return d;
}

}  // namespace isotouch::service
