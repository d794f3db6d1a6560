// ReportDevice over a scripted link (no I/O, deterministic): the newest accepted report is
// what the servo reads; duplicates and reordered reports are dropped, gaps, garbage counted;
// the force written reaches the link as an output report answering the report it used; a
// closed device's last output is a disabled zero force; a servo that stops writing gets a
// disabled zero on the link after the stall time; no first report -> a clear error;
// the I/O threads ask for SCHED_FIFO and a refusal is named in realtime_note().
#include <gtest/gtest.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <cmath>
#include <functional>
#include <deque>
#include <mutex>
#include <thread>

#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/device_protocols.h"
#include "isotouch/servo/hid_report.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/tests/sched_canary.h"
#include "isotouch/tests/unprivileged_child.h"

using namespace isotouch::core;
using namespace isotouch::servo;

namespace {
struct Script {
  std::mutex mu;
  int reader_policy = -1, reader_priority = -1;  // the reader thread's scheduling, as the kernel has it
  std::deque<std::vector<std::uint8_t>> in;   // reports the "device" sends
  std::vector<std::vector<std::uint8_t>> out; // reports the host wrote
  std::vector<std::int64_t> out_ns;            // when each was written (steady clock) [ns]
};

std::int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

class ScriptedLink final : public ReportLink {
 public:
  explicit ScriptedLink(Script& s) : s_(s) {}
  std::string name() const override { return "scripted"; }
  std::string open() override { return {}; }
  void close() override {}
  int read(std::span<std::uint8_t> buf, int) override {
    {
      std::lock_guard lock(s_.mu);
      sched_param sp{};
      s_.reader_policy = sched_getscheduler(0);
      s_.reader_priority = sched_getparam(0, &sp) == 0 ? sp.sched_priority : -1;
      if (!s_.in.empty()) {
        const auto r = s_.in.front();
        s_.in.pop_front();
        std::copy(r.begin(), r.end(), buf.begin());
        return int(r.size());
      }
    }
    std::this_thread::sleep_for(std::chrono::microseconds(200));
    return 0;
  }
  bool write(std::span<const std::uint8_t> r) override {
    std::lock_guard lock(s_.mu);
    s_.out.emplace_back(r.begin(), r.end());
    s_.out_ns.push_back(steady_ns());
    return true;
  }
  int get_feature(std::uint8_t, std::span<std::uint8_t> buf) override {
    DeviceCaps c;
    c.name = "scripted";
    c.max_force_n = 4;
    const auto b = hid::encode_caps(c);
    std::copy(b.begin(), b.end(), buf.begin());
    return int(b.size());
  }

 private:
  Script& s_;
};

std::vector<std::uint8_t> input(std::uint32_t seq, double z) {
  hid::InputReport r;
  r.sequence = seq;
  r.position_m = Vec3{0, 0, z};
  const auto b = hid::encode(r);
  return {b.begin(), b.end()};
}

void wait_for(const std::function<bool()>& done) {
  for (int i = 0; i < 2000 && !done(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}
}  // namespace

TEST(ReportDevice, DropsDuplicatesAndReorderedReportsAndCountsGapsAndGarbage) {
  Script s;
  s.in = {input(1, 0.001), input(2, 0.002), input(2, 0.020), input(4, 0.004), input(3, 0.030),
          std::vector<std::uint8_t>(32, 0xAB), input(5, 0.005)};
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>());
  dev.open();
  wait_for([&] { return dev.counters().reports >= 4 && dev.counters().garbage >= 1; });
  const LinkCounters c = dev.counters();
  EXPECT_EQ(c.reports, 4);     // 1, 2, 4, 5
  EXPECT_EQ(c.duplicates, 1);  // the second 2
  EXPECT_EQ(c.reordered, 1);   // 3 after 4
  EXPECT_EQ(c.gaps, 1);        // 3 missing between 2 and 4 (it came late, and was dropped)
  EXPECT_EQ(c.garbage, 1);
  EXPECT_NE(dev.last_refusal().find("report ID 171"), std::string::npos) << dev.last_refusal();
  const DeviceReading r = dev.read();
  EXPECT_EQ(r.sequence, 5u);
  EXPECT_NEAR(r.position_m.z, 0.005, 1e-9);  // never the duplicate's or the late report's
  EXPECT_EQ(r.status, DeviceStatus::kOk);
  EXPECT_GT(r.received_ns, 0);
  EXPECT_DOUBLE_EQ(dev.caps().max_force_n, 4.0);
  dev.close();
}

TEST(ReportDevice, TheForceGoesOutAnsweringItsReportAndEndsAsADisabledZero) {
  Script s;
  s.in = {input(7, 0.001)};
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>());
  dev.open();
  dev.enable_force(true, 0.5);
  dev.answer(dev.read().sequence);
  dev.write_force_n(Vec3{0, 0, 1.5});
  auto find = [&](hid::OutputReport& o) {
    std::lock_guard lock(s.mu);
    for (const auto& b : s.out)
      if (hid::decode(b, o) && o.enable && o.answers == 7) return true;
    return false;
  };
  hid::OutputReport o;
  wait_for([&] { return find(o); });
  ASSERT_TRUE(find(o));
  EXPECT_NEAR(o.force_n.z, 1.5, 1e-9);
  dev.write_force_n(Vec3{NAN, 0, 0});  // never sent as NaN
  dev.close();
  std::lock_guard lock(s.mu);
  ASSERT_FALSE(s.out.empty());
  hid::OutputReport last;
  ASSERT_TRUE(hid::decode(s.out.back(), last));
  EXPECT_FALSE(last.enable);
  EXPECT_EQ(last.force_n.x, 0.0);
  EXPECT_EQ(last.force_n.z, 0.0);
  for (const auto& b : s.out) {
    hid::OutputReport any;
    ASSERT_TRUE(hid::decode(b, any));
    EXPECT_TRUE(std::isfinite(any.force_n.x));
  }
}

// What the link carried from `from_ns` on: (time, decoded report), in order.
std::vector<std::pair<std::int64_t, hid::OutputReport>> sent_since(Script& s, std::int64_t from_ns) {
  std::lock_guard lock(s.mu);
  std::vector<std::pair<std::int64_t, hid::OutputReport>> out;
  for (std::size_t i = 0; i < s.out.size(); ++i) {
    hid::OutputReport o;
    if (s.out_ns[i] >= from_ns && hid::decode(s.out[i], o)) out.emplace_back(s.out_ns[i], o);
  }
  return out;
}

TEST(ReportDevice, AServoThatStopsWritingGetsADisabledZeroAfterTheStallTime) {
  isotouch::test::SchedCanary canary;  // how long the machine was gone while the writer timed the stall
  Script s;
  s.in = {input(7, 0.001)};
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>());
  dev.open();
  const double stall_s = 0.004;
  dev.enable_force(true, stall_s);
  const std::int64_t t0 = steady_ns();
  dev.write_force_n(Vec3{0, 0, 1.5});  // then nothing: a stalled servo
  std::this_thread::sleep_for(std::chrono::milliseconds(40));
  const auto stalled = sent_since(s, t0);
  const std::int64_t t1 = steady_ns();
  dev.write_force_n(Vec3{0, 0, 0.25});  // the servo is back
  wait_for([&] { return !sent_since(s, t1).empty(); });
  const std::int64_t t2 = steady_ns();
  dev.write_force_n(Vec3{0, 0, 0.25});  // and ramping
  wait_for([&] { return !sent_since(s, t2).empty(); });
  const auto back = sent_since(s, t1);
  const auto ramped = sent_since(s, t2);
  const LinkCounters c = dev.counters();
  dev.close();

  // On the link: the force, then (no earlier than the stall time after the write, and
  // soon after it) a zero with enable cleared, and nothing enabled until the next write.
  // (A keep-alive of the state before the write may go out first: skip those.)
  std::size_t on = 0;
  while (on < stalled.size() && !stalled[on].second.enable) ++on;
  ASSERT_LT(on, stalled.size()) << "the write never went out";
  EXPECT_NEAR(stalled[on].second.force_n.z, 1.5, 1e-9);
  std::size_t off = on;
  while (off < stalled.size() && stalled[off].second.enable) ++off;
  ASSERT_LT(off, stalled.size()) << "the force stayed enabled for 40 ms without a write";
  EXPECT_GE(stalled[off].first - t0, std::int64_t(stall_s * 1e9));
  EXPECT_LE(stalled[off].first - t0, std::int64_t((stall_s + 0.005) * 1e9) + canary.lost_ns(t0, stalled[off].first))
      << canary.describe(t0, stalled[off].first);
  for (std::size_t i = off; i < stalled.size(); ++i) {
    EXPECT_FALSE(stalled[i].second.enable) << "report " << i;
    EXPECT_EQ(stalled[i].second.force_n.z, 0.0) << "report " << i;
  }
  EXPECT_GE(stalled.size() - off, 3u) << "the disabled zero is kept alive (every 10 ms)";
  // Back: the first write after the stall goes out as an enabled zero (the servo ramps in
  // from there), the next as written.
  ASSERT_FALSE(back.empty());
  EXPECT_TRUE(back.front().second.enable);
  EXPECT_EQ(back.front().second.force_n.z, 0.0) << "the first write after the stall jumped back to force";
  ASSERT_FALSE(ramped.empty());
  EXPECT_TRUE(ramped.front().second.enable);
  EXPECT_NEAR(ramped.front().second.force_n.z, 0.25, 1e-9);
  EXPECT_EQ(c.stalls, 1);
}

namespace {
/// The voluntary context switches (wake-ups after sleeping) of this process's thread named
/// `comm`, as the kernel counts them (/proc/self/task/TID/status); -1 if there is none.
long thread_wakeups(const std::string& comm) {
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream c(task.path() / "comm");
    std::string name;
    std::getline(c, name);
    if (name != comm) continue;
    std::ifstream st(task.path() / "status");
    for (std::string line; std::getline(st, line);)
      if (line.rfind("voluntary_ctxt_switches:", 0) == 0) return std::stol(line.substr(24));
  }
  return -1;
}
}  // namespace

// The writer's model of the servo: the shortest interval per write; asleep until a lead
// of max(3 polls, 1/8 interval) before the next write is due, polling inside that window.
TEST(WriteInterval, LearnsTheServosIntervalAndLooksShortlyBeforeItsNextWrite) {
  WriteInterval w;
  EXPECT_EQ(w.estimate_ns(), 0);
  w.saw(0, 1);
  EXPECT_EQ(w.estimate_ns(), 0);                           // one write: no interval yet
  EXPECT_EQ(w.next_look_ns(0, 20'000), 20'000);            // polls meanwhile
  w.saw(1'000'000, 1);
  EXPECT_EQ(w.estimate_ns(), 1'000'000);
  // Asleep until a lead of max(3 polls, 1/8 interval) = 125 us before the next write is due.
  EXPECT_EQ(w.next_look_ns(1'000'000, 20'000), 1'875'000);
  EXPECT_EQ(w.next_look_ns(1'900'000, 20'000), 1'920'000);  // inside the window: polls
  w.saw(1'990'000, 1);                                     // found while polling: when seen
  EXPECT_EQ(w.estimate_ns(), 990'000);                     // the shortest interval
  EXPECT_EQ(w.next_look_ns(1'990'000, 20'000), 1'990'000 + 990'000 - 123'750);
  // It woke 600 us late and found the write there: taken as written when due (2,980 us), so
  // the next window opens a lead before 3,970 us, not 600 us later.
  w.saw(3'580'000, 1);
  EXPECT_EQ(w.next_look_ns(3'580'000, 20'000), 2'980'000 + 990'000 - 123'750);
  EXPECT_EQ(w.next_look_ns(3'900'000, 20'000), 3'920'000);
  w.saw(5'940'000, 2);                                     // two writes seen at once: 1,480 us each
  EXPECT_EQ(w.estimate_ns(), 990'000);
}

// A servo writing at 1 kHz for 1 s: the writer thread sleeps between its writes (the kernel
// counts fewer than 8 wake-ups a write: 2-5 here; polling every 20 us, 13 here and up to 50) and 90% of
// the writes or more reach the link, half within 200 us less the time the
// canaries (sched_canary.h) saw the machine gone inside each delay.
// Under ThreadSanitizer every memory access of both threads is instrumented (several times
// slower, unevenly): the writer's timing figures (writes that reached the link, their delay)
// are checked in the plain build; the sanitizer build runs the same code for its races.
#if defined(__SANITIZE_THREAD__)
constexpr bool kRealTimeFigures = false;
#else
constexpr bool kRealTimeFigures = true;
#endif

TEST(ReportDevice, TheWriterSleepsBetweenTheServosWritesAndSendsEachOnTime) {
  Script s;
  s.in = {input(7, 0.001)};
  ReportDeviceOptions opt;
  opt.fifo_priority = geteuid() == 0 ? 70 : 0;  // as isotouch-sculpt runs it, where allowed
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>(), opt);
  dev.open();
  dev.enable_force(true, 0.0025);
  const long w0 = thread_wakeups("devio-writer");
  ASSERT_GE(w0, 0) << "no thread named devio-writer";
  isotouch::test::SchedCanary canary;  // how long the machine was gone while each write waited
  constexpr int kWrites = 1000;
  std::vector<std::int64_t> written(kWrites);
  // The servo's writes, from a thread at the servo's SCHED_FIFO priority where allowed (the
  // servo runs so): a loaded machine's late test thread is not the writer under test.
  std::thread servo([&] {
    if (geteuid() == 0) isotouch::servo::make_thread_realtime("test servo", true, 80, false, -1);
    std::int64_t next = steady_ns();  // steady_clock is CLOCK_MONOTONIC
    for (int k = 0; k < kWrites; ++k) {
      next += 1'000'000;
      const timespec ts{time_t(next / 1000000000LL), long(next % 1000000000LL)};
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
      }
      written[std::size_t(k)] = steady_ns();
      dev.write_force_n(Vec3{0, 0, 1e-3 * (k + 1)});  // millinewton steps: each write told apart on the link
    }
  });
  servo.join();
  const long wakes = thread_wakeups("devio-writer") - w0;
  dev.close();
  canary.stop();
  // Each write's delay less the time the canaries saw the machine gone in it (a vCPU the VM
  // lost, a wake-up the kernel made late for every thread alike): the writer's own latency.
  std::vector<std::int64_t> delay_ns;
  std::vector<bool> seen(kWrites, false);
  std::int64_t lost_in_delays = 0;
  for (const auto& [t, o] : sent_since(s, written.front() - 1)) {
    const long k = std::lround(o.force_n.z * 1e3) - 1;
    if (!o.enable || k < 0 || k >= kWrites || seen[std::size_t(k)]) continue;
    seen[std::size_t(k)] = true;
    const std::int64_t lost = canary.lost_ns(written[std::size_t(k)], t);
    lost_in_delays += lost;
    delay_ns.push_back(std::max<std::int64_t>(0, t - written[std::size_t(k)] - lost));
  }
  EXPECT_LT(wakes, 8 * kWrites) << "the writer woke " << wakes << " times for " << kWrites << " writes";
  ASSERT_FALSE(delay_ns.empty());
  if (!kRealTimeFigures) return;  // (the writer's code ran, under the sanitizer's eyes, above)
  // A write the next one replaced before the writer looked is not sent (the latest value
  // wins); this thread's own sleeps are late now and then on a loaded machine.
  EXPECT_GE(delay_ns.size(), std::size_t(kWrites * 90 / 100)) << "writes that never reached the link";
  std::nth_element(delay_ns.begin(), delay_ns.begin() + long(delay_ns.size() / 2), delay_ns.end());
  EXPECT_LE(delay_ns[delay_ns.size() / 2], 200'000)
      << "median write-to-link delay [ns], less the lost time; "
      << canary.describe(written.front(), written.back()) << "; " << lost_in_delays / 1000
      << " us of it inside the delays";
}

TEST(ReportDevice, NoFirstReportIsAClearError) {
  Script s;
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>());
  try {
    dev.open();
    FAIL() << "opened without a report";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("scripted: no input report within 1 s"), std::string::npos) << e.what();
  }
}

TEST(ReportDevice, TheIoThreadsAskForSchedFifoAndARefusalIsNamed) {
  if (geteuid() != 0) GTEST_SKIP() << "needs root: FIFO granted here, refused in a child that gives it up";
  ReportDeviceOptions opt;
  opt.fifo_priority = 60;
  {
    Script s;
    s.in = {input(1, 0.001)};
    ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>(), opt);
    dev.open();
    EXPECT_EQ(dev.realtime_note(), "");
    std::lock_guard lock(s.mu);
    EXPECT_EQ(s.reader_policy, SCHED_FIFO);
    EXPECT_EQ(s.reader_priority, 60);
  }
  // A child without root (and so without CAP_SYS_NICE): refused, named, the default policy.
  const int code = isotouch::test::run_unprivileged([&] {
    Script s;
    s.in = {input(1, 0.001)};
    ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>(), opt);
    dev.open();
    const std::string note = dev.realtime_note();
    int fail = 0;
    if (note.find("scripted device threads: SCHED_FIFO priority 60 refused") == std::string::npos) fail = 1;
    else if (note.find('\n') != std::string::npos) fail = 2;  // one line for the log
    {
      std::lock_guard lock(s.mu);
      if (s.reader_policy == SCHED_FIFO) fail = 3;
    }
    dev.close();
    return fail;
  });
  if (code == isotouch::test::kCouldNotDrop) GTEST_SKIP() << "could not drop to uid 65534 (a user namespace without it?)";
  EXPECT_EQ(code, 0) << "1: the note does not name the link and the refusal, 2: not one line, 3: FIFO, 11: threw, -1: crashed";
}

namespace {
/// A device's input reports at about 1 kHz: the next one into `buf` (its size) once a
/// millisecond has passed since the last, else 0.
struct ReportClock {
  std::uint32_t seq = 0;
  std::chrono::steady_clock::time_point last{};
  int report(std::span<std::uint8_t> buf) {
    const auto now = std::chrono::steady_clock::now();
    if (now - last < std::chrono::milliseconds(1)) return 0;
    last = now;
    const auto b = input(++seq, 0.001);
    std::copy(b.begin(), b.end(), buf.begin());
    return int(b.size());
  }
};

/// A link double with hidapi's hazard: every call frees and replaces one per-handle error
/// string (a plain pointer, as in hidapi 0.13) and takes a while; a call that starts while
/// another is in progress is counted (and ThreadSanitizer reports the string's race).
/// Reports arrive at about 1 kHz; wait_readable() is the default (it may overlap).
class OverlapLink final : public ReportLink {
 public:
  std::string name() const override { return "overlap"; }
  std::string open() override { return call([] { return std::string(); }); }
  void close() override {}
  int read(std::span<std::uint8_t> buf, int) override {
    return call([&] { return clock_.report(buf); });
  }
  bool write(std::span<const std::uint8_t>) override {
    return call([&] {
      writes.fetch_add(1);
      return true;
    });
  }
  int get_feature(std::uint8_t, std::span<std::uint8_t> buf) override {
    return call([&] {
      DeviceCaps c;
      c.watchdog_s = 0.05;
      const auto b = hid::encode_caps(c);
      std::copy(b.begin(), b.end(), buf.begin());
      return int(b.size());
    });
  }
  ~OverlapLink() override { delete error_; }
  std::atomic<long> overlaps{0}, writes{0};

 private:
  template <class F>
  auto call(F f) -> decltype(f()) {
    if (busy_.exchange(true)) overlaps.fetch_add(1);
    delete error_;  // hid_read_timeout and hid_write both start so
    error_ = new std::string("no error");
    const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(30);
    while (std::chrono::steady_clock::now() < until) {
    }
    auto r = f();
    busy_.store(false);
    return r;
  }
  std::atomic<bool> busy_{false};
  std::string* error_ = nullptr;
  ReportClock clock_;
};
}  // namespace

TEST(ReportDevice, NoLinkCallOverlapsAnotherWhileReportsAndForcesFlow) {
  auto owned = std::make_unique<OverlapLink>();
  OverlapLink& link = *owned;
  ReportDevice dev(std::move(owned), std::make_unique<V1Protocol>());
  dev.open();
  dev.enable_force(true, 0);
  // A servo's forces for 300 ms, and on until 300 went out and 100 reports came in (a
  // loaded machine takes longer; 10 s at most): the writer sends while the reader reads.
  const auto start = std::chrono::steady_clock::now();
  auto more = [&] {
    const auto t = std::chrono::steady_clock::now() - start;
    if (t > std::chrono::seconds(10)) return false;
    return t < std::chrono::milliseconds(300) || link.writes.load() <= 300 || dev.counters().reports <= 100;
  };
  for (int k = 0; more(); ++k) {
    dev.write_force_n(Vec3{0, 0, 0.001 * (k % 100)});
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  dev.close();
  EXPECT_GT(dev.counters().reports, 100);
  EXPECT_GT(link.writes.load(), 300);
  EXPECT_EQ(link.overlaps.load(), 0) << "a read and a write (or open, close) ran at once";
}

namespace {
/// A device that reports at about 1 kHz, drops its link when told and comes back with the
/// capabilities the test set (another device plugged in).
class ReplugLink final : public ReportLink {
 public:
  std::string name() const override { return "replug"; }
  std::string open() override { return {}; }
  void close() override {}
  int read(std::span<std::uint8_t> buf, int) override {
    if (unplug.exchange(false)) return -1;
    return clock_.report(buf);
  }
  bool write(std::span<const std::uint8_t>) override { return true; }
  int get_feature(std::uint8_t, std::span<std::uint8_t> buf) override {
    std::lock_guard lock(mu);
    const auto b = hid::encode_caps(caps);
    std::copy(b.begin(), b.end(), buf.begin());
    return int(b.size());
  }
  std::mutex mu;
  DeviceCaps caps;
  std::atomic<bool> unplug{false};

 private:
  ReportClock clock_;
};

DeviceCaps known_caps() {
  DeviceCaps c;
  c.name = "known";
  c.max_force_n = 4;
  c.max_stiffness_n_per_m = 2000;
  c.workspace_min_m = Vec3{-0.1, -0.1, -0.1};
  c.workspace_max_m = Vec3{0.1, 0.1, 0.1};
  c.watchdog_s = 0.05;
  return c;
}
}  // namespace

TEST(ReportDevice, AReconnectedDeviceWithOtherCapabilitiesIsRefusedNamingTheField) {
  struct Case {
    const char* field;  // what last_error must say
    void (*change)(DeviceCaps&);
  };
  const Case cases[] = {
      {"name 'other' differs from 'known' at open", [](DeviceCaps& c) { c.name = "other"; }},
      {"maximum force [N] 8 differs from 4 at open", [](DeviceCaps& c) { c.max_force_n = 8; }},
      {"workspace maximum [m] (0.1, 0.2, 0.1) differs from (0.1, 0.1, 0.1) at open",
       [](DeviceCaps& c) { c.workspace_max_m.y = 0.2; }},
      {"maximum stiffness [N/m] 5000 differs from 2000 at open", [](DeviceCaps& c) { c.max_stiffness_n_per_m = 5000; }},
  };
  ReportDeviceOptions opt;
  opt.reconnect_interval_s = 0.002;
  for (const Case& k : cases) {
    auto owned = std::make_unique<ReplugLink>();
    ReplugLink& link = *owned;
    link.caps = known_caps();
    ReportDevice dev(std::move(owned), std::make_unique<V1Protocol>(), opt);
    dev.open();
    {
      std::lock_guard lock(link.mu);
      k.change(link.caps);  // another device on the same port
    }
    link.unplug = true;
    wait_for([&] { return dev.last_error().find("refused") != std::string::npos; });
    EXPECT_NE(dev.last_error().find("replug: the reconnected device is refused, the link stays down: " + std::string(k.field)),
              std::string::npos)
        << dev.last_error();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // several more attempts
    EXPECT_EQ(dev.counters().reconnects, 0) << k.field;
    EXPECT_EQ(dev.read().status, DeviceStatus::kDisconnected) << k.field;
    {
      std::lock_guard lock(link.mu);
      link.caps = known_caps();  // the device the scene was checked against is back
    }
    wait_for([&] { return dev.counters().reconnects == 1; });
    EXPECT_EQ(dev.counters().reconnects, 1) << k.field;
    dev.close();
  }
}

namespace {
std::vector<std::uint8_t> input_flags(std::uint32_t seq, std::uint16_t flags) {
  hid::InputReport r;
  r.sequence = seq;
  r.flags = flags;
  const auto b = hid::encode(r);
  return {b.begin(), b.end()};
}
}  // namespace

TEST(ReportDevice, TheDeviceForceFlagsReachTheServoAndWatchdogTripsAreCounted) {
  Script s;
  s.in = {input_flags(1, hid::kForceEnabled), input_flags(2, hid::kWatchdog), input_flags(3, hid::kWatchdog),
          input_flags(4, hid::kForceEnabled)};
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>());
  dev.open();
  wait_for([&] { return dev.counters().reports >= 4; });
  EXPECT_EQ(dev.counters().watchdog_trips, 1);  // reports 2 and 3: one trip
  EXPECT_NE(dev.last_error().find("scripted: the device's watchdog zeroed its force (no output report within 0 ms)"),
            std::string::npos)
      << dev.last_error();
  DeviceReading r = dev.read();
  EXPECT_FALSE(r.force_off);
  EXPECT_FALSE(r.watchdog_tripped);
  {
    std::lock_guard lock(s.mu);
    s.in = {input_flags(5, hid::kWatchdog)};
  }
  wait_for([&] { return dev.counters().reports >= 5; });
  r = dev.read();
  EXPECT_TRUE(r.force_off);  // the enabled flag is clear
  EXPECT_TRUE(r.watchdog_tripped);
  EXPECT_EQ(dev.counters().watchdog_trips, 2);
  dev.close();
}

TEST(ReportDevice, ADeviceWithoutAWatchdogIsWarnedAbout) {
  Script s;
  s.in = {input(1, 0.001)};
  ReportDevice dev(std::make_unique<ScriptedLink>(s), std::make_unique<V1Protocol>());  // watchdog 0 ms
  dev.open();
  EXPECT_NE(dev.warning().find("scripted: scripted has no watchdog (0 ms in its capabilities)"), std::string::npos)
      << dev.warning();
  dev.close();
  auto link = std::make_unique<ReplugLink>();
  link->caps = known_caps();  // a 50 ms watchdog
  ReportDevice with(std::move(link), std::make_unique<V1Protocol>());
  with.open();
  EXPECT_EQ(with.warning(), "");
}
