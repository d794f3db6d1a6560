#include "isotouch/servo/report_device.h"

#include <pthread.h>
#include <sys/prctl.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <sstream>
#include <stdexcept>

#include "isotouch/servo/cpu_placement.h"

namespace isotouch::servo {
namespace {
std::int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}
void sleep_ns(std::int64_t ns) {
  const timespec ts{time_t(ns / 1000000000LL), long(ns % 1000000000LL)};
  nanosleep(&ts, nullptr);
}
void sleep_until_ns(std::int64_t t) {
  const timespec ts{time_t(t / 1000000000LL), long(t % 1000000000LL)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}
constexpr std::size_t kMaxReport = 256;

std::string text(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}
std::string text(const Vec3& v) {
  std::ostringstream o;
  o << '(' << v.x << ", " << v.y << ", " << v.z << ')';
  return o.str();
}
bool same(const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

/// "" if `now` is the device `then` described, else the first field that differs with both
/// values (what the scene was checked against: name, force, workspace, stiffness, damping).
std::string caps_difference(const DeviceCaps& then, const DeviceCaps& now) {
  auto differs = [](const std::string& field, const std::string& a, const std::string& b) {
    return field + " " + b + " differs from " + a + " at open";
  };
  if (now.name != then.name) return differs("name", "'" + then.name + "'", "'" + now.name + "'");
  if (now.dof != then.dof) return differs("degrees of freedom", text(then.dof), text(now.dof));
  if (now.max_force_n != then.max_force_n)
    return differs("maximum force [N]", text(then.max_force_n), text(now.max_force_n));
  if (!same(now.workspace_min_m, then.workspace_min_m))
    return differs("workspace minimum [m]", text(then.workspace_min_m), text(now.workspace_min_m));
  if (!same(now.workspace_max_m, then.workspace_max_m))
    return differs("workspace maximum [m]", text(then.workspace_max_m), text(now.workspace_max_m));
  if (now.max_stiffness_n_per_m != then.max_stiffness_n_per_m)
    return differs("maximum stiffness [N/m]", text(then.max_stiffness_n_per_m), text(now.max_stiffness_n_per_m));
  if (now.max_damping_n_s_per_m != then.max_damping_n_s_per_m)
    return differs("maximum damping [N s/m]", text(then.max_damping_n_s_per_m), text(now.max_damping_n_s_per_m));
  return {};
}
}  // namespace

bool ReportLink::wait_readable(int timeout_ms) {
  sleep_ns(std::min<std::int64_t>(std::int64_t(timeout_ms) * 1'000'000, kPollUs * 1'000LL));
  return true;
}

ReportDevice::ReportDevice(std::unique_ptr<ReportLink> link, std::unique_ptr<DeviceProtocol> protocol,
                           ReportDeviceOptions options)
    : link_(std::move(link)), protocol_(std::move(protocol)), opt_(options) {
  DeviceReading r;
  r.status = DeviceStatus::kDisconnected;
  reading_.store(r);
  last_read_ = r;
}

ReportDevice::~ReportDevice() { close(); }

void ReportDevice::open() {
  if (reader_.joinable()) return;
  if (std::string e = link_->open(); !e.empty()) throw std::runtime_error(link_->name() + ": " + e);
  if (std::string e = protocol_->handshake(*link_, caps_); !e.empty()) {
    link_->close();
    throw std::runtime_error(link_->name() + ": " + e);
  }
  if (!(caps_.watchdog_s > 0))
    warning_ = link_->name() + ": " + caps_.name +
               " has no watchdog (0 ms in its capabilities): if the host stops sending, its last force stays on";
  up_ = true;
  stop_ = false;
  reader_ = std::thread([this] { reader_loop(); });
  writer_ = std::thread([this] { writer_loop(); });
  // Named for /proc/PID/task/TID/comm and top -H (before open() returns).
  pthread_setname_np(reader_.native_handle(), "devio-reader");
  pthread_setname_np(writer_.native_handle(), "devio-writer");
  // The servo starts on a live reading, not on the initial "disconnected" one.
  for (int i = 0; i < 1000 && reports_.load() == 0; ++i) sleep_ns(1'000'000);
  if (reports_.load() == 0) {
    const std::string why = last_error();
    close();
    throw std::runtime_error(link_->name() + ": no input report within 1 s" + (why.empty() ? "" : " (" + why + ")"));
  }
}

void ReportDevice::close() {
  if (!reader_.joinable()) return;
  rule_.disable();
  stop_ = true;
  writer_.join();  // its last report: a disabled zero force
  reader_.join();
  std::lock_guard lock(link_mu_);
  link_->close();
  up_ = false;
}

void ReportDevice::write_force_n(const Vec3& force_n) {
  // Servo thread: one store into the latest-value cell, no syscall (non-finite: zero; the
  // first write after a stall: zero). Unstamped: the writer polls every write_poll_us.
  rule_.write(force_n, answers_);
}

const std::atomic<std::uint64_t>* ReportDevice::enable_force(bool on, double stall_s) {
  return rule_.enable(on, stall_s, opt_.default_stall_s, now_ns());
}

DeviceCaps ReportDevice::caps() const { return caps_; }

LinkCounters ReportDevice::counters() const {
  LinkCounters c;
  c.reports = reports_.load(), c.garbage = garbage_.load(), c.gaps = gaps_.load();
  c.duplicates = duplicates_.load(), c.reordered = reordered_.load(), c.disconnects = disconnects_.load();
  c.reconnects = reconnects_.load(), c.writes = sent_.load(), c.write_errors = write_errors_.load();
  c.watchdog_trips = watchdog_trips_.load(), c.busy_reads = long(reading_.misses());
  c.stalls = long(rule_.stalls());
  return c;
}

std::string ReportDevice::last_error() const {
  std::lock_guard lock(note_mu_);
  return last_error_;
}

std::string ReportDevice::last_refusal() const {
  std::lock_guard lock(note_mu_);
  return last_refusal_;
}

void ReportDevice::note(const std::string& error, bool refusal) {
  std::lock_guard lock(note_mu_);
  last_error_ = error;
  if (refusal) last_refusal_ = error;
}

void ReportDevice::unnote(const std::string& error) {
  std::lock_guard lock(note_mu_);
  if (last_refusal_ == error) last_refusal_.clear();
  if (last_error_ == error) last_error_.clear();
}

void ReportDevice::link_down(const std::string& why) {
  DeviceReading r = reading_.load();
  r.status = DeviceStatus::kDisconnected;
  reading_.store(r);  // the servo's next tick sends zero force
  {
    std::lock_guard lock(link_mu_);
    up_ = false;
    link_->close();
  }
  disconnects_.fetch_add(1);
  note(link_->name() + ": link down (" + why + ")");
}

bool ReportDevice::reconnect() {
  std::lock_guard lock(link_mu_);
  if (!link_->open().empty()) return false;
  // The scene was checked against the capabilities read at open: another device is refused.
  DeviceCaps c;
  if (!protocol_->handshake(*link_, c).empty()) {
    link_->close();  // not answering yet (an emulator going away or starting): try again
    return false;
  }
  if (const std::string e = caps_difference(caps_, c); !e.empty()) {
    link_->close();
    note(link_->name() + ": the reconnected device is refused, the link stays down: " + e);
    return false;
  }
  up_ = true;
  ++connection_;
  have_sequence_ = false;  // a restarted device counts from anywhere
  reconnects_.fetch_add(1);
  return true;
}

void ReportDevice::accept(const DeviceReading& in) {
  if (protocol_->sequenced()) {
    const std::uint32_t seq = std::uint32_t(in.sequence);
    const std::uint32_t step = seq - last_sequence_;  // modulo 2^32
    if (have_sequence_ && step == 0) {
      duplicates_.fetch_add(1);
      return;
    }
    if (have_sequence_ && step > 0x80000000u) {
      reordered_.fetch_add(1);
      return;
    }
    if (have_sequence_ && step > 1) gaps_.fetch_add(long(step - 1));
    last_sequence_ = seq;
    have_sequence_ = true;
  }
  if (in.watchdog_tripped && !tripped_) {
    watchdog_trips_.fetch_add(1);
    note(link_->name() + ": the device's watchdog zeroed its force (no output report within " +
         text(caps_.watchdog_s * 1e3) + " ms)");
  }
  tripped_ = in.watchdog_tripped;
  DeviceReading r = in;
  r.received_ns = now_ns();
  r.connection = connection_;
  reading_.store(r);
  reports_.fetch_add(1);
}

void ReportDevice::ask_fifo() {
  if (opt_.fifo_priority <= 0) return;
  // SCHED_FIFO only: the device threads are not pinned (the servo thread owns its CPU).
  std::string note = make_thread_realtime(link_->name() + " device threads", true, opt_.fifo_priority, false, -1).note;
  if (note.empty()) return;
  if (note.back() == '\n') note.pop_back();
  std::lock_guard lock(note_mu_);
  realtime_note_ = note;
}

std::string ReportDevice::realtime_note() const {
  std::lock_guard lock(note_mu_);
  return realtime_note_;
}

void ReportDevice::reader_loop() {
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);  // a link without its own wait sleeps kPollUs
  ask_fifo();
  std::array<std::uint8_t, kMaxReport> buf{};
  std::array<std::uint8_t, kMaxReport> cmd{};
  const auto retry_ns = std::int64_t(opt_.reconnect_interval_s * 1e9);
  while (!stop_.load()) {
    if (!up_.load()) {
      if (!reconnect()) sleep_ns(retry_ns);
      continue;
    }
    // Wait outside the lock, read without waiting inside it: every link call is serialized
    // and the writer waits for a read of what is already there, never for a timeout.
    if (!link_->wait_readable(20)) continue;  // the servo judges staleness from received_ns
    int n = 0;
    {
      std::lock_guard lock(link_mu_);
      n = link_->read(buf, 0);
    }
    if (n < 0) {
      link_down("read failed or end of stream");
      continue;
    }
    if (n == 0) continue;  // the servo judges staleness from received_ns
    DeviceReading r;
    if (std::string e = protocol_->decode_input(std::span(buf.data(), std::size_t(n)), r); !e.empty()) {
      garbage_.fetch_add(1);
      note(link_->name() + ": refused " + e, true);
      continue;
    }
    accept(r);
    // The protocol's reason, noted when it changes (the reader allocates only then, not per
    // report); a reading without a fault ends the run, so a later fault is noted again.
    if (r.status == DeviceStatus::kFault || r.status == DeviceStatus::kUncalibrated) {
      if (const std::string_view why = protocol_->fault(); !why.empty() && why != fault_noted_) {
        fault_noted_.assign(why);
        note(link_->name() + ": " + fault_noted_, true);
      }
    } else if (!fault_noted_.empty()) {
      // Over (calibrated since): the reason no longer holds, and is taken back.
      unnote(link_->name() + ": " + fault_noted_);
      fault_noted_.clear();  // keeps its capacity
    }
    if (const std::size_t m = protocol_->pending_command(cmd)) send(std::span(cmd.data(), m));
  }
}

bool ReportDevice::send(std::span<const std::uint8_t> report) {
  std::lock_guard lock(link_mu_);
  if (!up_.load()) return false;
  if (!link_->write(report)) {
    write_errors_.fetch_add(1);
    return false;
  }
  sent_.fetch_add(1);
  return true;
}

void WriteInterval::saw(std::int64_t t_ns, std::uint64_t writes) {
  // Found on the first look after sleeping to the window, later than it was due: the writer
  // woke late, not the servo wrote late; taken as written when due, so a late wake-up does
  // not carry into the next window. Found while polling: when it was seen.
  const std::int64_t T = estimate_ns();
  std::int64_t at = t_ns;
  if (slept_ && T > 0 && last_ns_ >= 0 && writes == 1) at = std::min(t_ns, last_ns_ + T);
  if (last_ns_ >= 0 && writes > 0) ring_[next_++ % ring_.size()] = (at - last_ns_) / std::int64_t(writes);
  last_ns_ = at;
}

std::int64_t WriteInterval::estimate_ns() const {
  std::int64_t best = 0;
  for (std::int64_t d : ring_)
    if (d > 0 && (best == 0 || d < best)) best = d;
  return best;
}

std::int64_t WriteInterval::next_look_ns(std::int64_t now_ns, std::int64_t poll_ns) {
  const std::int64_t poll = now_ns + poll_ns;
  const std::int64_t T = estimate_ns();
  slept_ = false;
  if (T <= 0 || last_ns_ < 0) return poll;
  const std::int64_t lead = std::max(3 * poll_ns, T / 8);
  const std::int64_t window = last_ns_ + T - lead;
  slept_ = window > poll;
  return std::max(poll, window);
}

void ReportDevice::writer_loop() {
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);  // wake on time: the poll is the latency
  ask_fifo();
  std::array<std::uint8_t, kMaxReport> buf{};
  const auto poll_ns = std::int64_t(opt_.write_poll_us * 1e3);
  const auto keepalive_ns = std::int64_t(opt_.keepalive_s * 1e9);
  rule_.restart(now_ns());
  std::int64_t last_send = 0;
  bool was_on = false;
  WriteInterval interval;
  while (!stop_.load()) {
    // The clock first: a count unchanged after it means no write up to t (read the other way
    // round, a preempted writer could call a write it has not loaded yet a stall). The stall
    // rule (stall_rule.h): force only while enabled and the servo writes; after the stall
    // time without a write (a slow renderer, a starved or stopped servo thread) zero with
    // enable cleared until a write made after the servo could see it.
    const std::int64_t t = now_ns();
    const StallLook l = rule_.look(t);
    if (l.fresh) interval.saw(t, l.new_writes);
    if (l.fresh || l.on != was_on || t - last_send >= keepalive_ns) {
      // Disabled or stalled: a zero force with enable cleared (the device keeps reporting).
      const std::size_t n = protocol_->encode_output(l.force_n, l.on, l.answers, buf);
      send(std::span(buf.data(), n));
      last_send = t;
      was_on = l.on;
    }
    // Asleep until shortly before the servo's next write is due, then polling: not 50,000
    // wake-ups a second at SCHED_FIFO beside the renderer. Never past the stall time or the
    // keepalive (the window ends before either: it closes a lead before one interval).
    sleep_until_ns(std::min({interval.next_look_ns(t, poll_ns), rule_.stall_at_ns(), last_send + keepalive_ns}));
  }
  const std::size_t n = protocol_->encode_output({}, false, 0, buf);
  send(std::span(buf.data(), n));
}

}  // namespace isotouch::servo
