// ReportDevice over a scripted link (no I/O, deterministic): the newest accepted report is
// what the servo reads; duplicates and reordered reports are dropped, gaps, garbage counted;
// the force written reaches the link as an output report answering the report it used; a
// closed device's last output is a disabled zero force; a servo that stops writing gets a
// disabled zero on the link after the stall time; no first report -> a clear error;
// the I/O threads ask for SCHED_FIFO and a refusal is named in realtime_note().
#include <gtest/gtest.h>
#include <sched.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <deque>
#include <mutex>
#include <thread>

#include "device_protocols.h"
#include "hid_report.h"
#include "report_device.h"
#include "unprivileged_child.h"

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
  ASSERT_FALSE(stalled.empty());
  EXPECT_TRUE(stalled.front().second.enable);
  EXPECT_NEAR(stalled.front().second.force_n.z, 1.5, 1e-9);
  std::size_t off = 0;
  while (off < stalled.size() && stalled[off].second.enable) ++off;
  ASSERT_LT(off, stalled.size()) << "the force stayed enabled for 40 ms without a write";
  EXPECT_GE(stalled[off].first - t0, std::int64_t(stall_s * 1e9));
  EXPECT_LE(stalled[off].first - t0, std::int64_t((stall_s + 0.005) * 1e9));
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
