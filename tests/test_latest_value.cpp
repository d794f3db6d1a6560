// LatestValue, the seqlock cell between the device reader and the servo: loads see whole
// values only; while a store is held in progress (a writer preempted inside it) the bounded
// load gives up at once, keeps the caller's last value and counts it; the waiting load waits.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <thread>

#include "isotouch/servo/latest_value.h"

namespace isotouch::servo {
/// Holds a store in progress, as a writer preempted between its first and last word would.
struct LatestValueTest {
  template <class T>
  static void begin_store(LatestValue<T>& c) { c.seq_.fetch_add(1); }
  template <class T>
  static void end_store(LatestValue<T>& c) { c.seq_.fetch_add(1); }
};
}  // namespace isotouch::servo

using isotouch::servo::LatestValue;
using isotouch::servo::LatestValueTest;

namespace {
struct Words {
  std::array<std::uint64_t, 7> w{};  // as large as a DeviceReading
};
Words all(std::uint64_t k) {
  Words v;
  v.w.fill(k);
  return v;
}
}  // namespace

TEST(LatestValue, ABoundedLoadKeepsTheLastValueWhileAStoreIsHeldAndCountsIt) {
  LatestValue<Words> cell(all(1));
  Words last;
  ASSERT_TRUE(cell.load(last));
  EXPECT_EQ(last.w[0], 1u);
  cell.store(all(2));
  LatestValueTest::begin_store(cell);  // the writer stops inside its next store
  std::atomic<int> result{-1};
  Words seen = last;
  std::thread servo([&] { result = cell.load(seen) ? 1 : 0; });
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (result.load() < 0 && std::chrono::steady_clock::now() < give_up) std::this_thread::yield();
  const bool returned = result.load() >= 0;
  LatestValueTest::end_store(cell);  // let an unbounded load finish, so the test ends
  servo.join();
  ASSERT_TRUE(returned) << "load() waited for the store in progress";
  EXPECT_EQ(result.load(), 0);
  EXPECT_EQ(seen.w, last.w) << "not the caller's last value";
  EXPECT_EQ(cell.misses(), 1u);
  ASSERT_TRUE(cell.load(seen));  // the store is over: the newest value again
  EXPECT_EQ(seen.w, all(2).w);
  EXPECT_EQ(cell.misses(), 1u);
}

TEST(LatestValue, ConcurrentLoadsSeeWholeValuesOnly) {
  LatestValue<Words> cell(all(0));
  std::atomic<bool> stop{false};
  std::thread writer([&] {
    // A store, then a short gap, as a device's reports come (back-to-back stores would leave
    // a bounded reader nothing but stores in progress on two busy cores).
    for (std::uint64_t k = 1; !stop.load(std::memory_order_relaxed); ++k) {
      cell.store(all(k));
      for (volatile int gap = 0; gap < 200; gap = gap + 1) {
      }
    }
  });
  Words v = all(0);
  long ok = 0, torn = 0;
  std::uint64_t newest = 0;
  for (int i = 0; i < 200000; ++i) {
    if (!cell.load(v)) continue;
    ++ok;
    for (std::uint64_t x : v.w) torn += x != v.w[0];
    EXPECT_GE(v.w[0], newest);  // never older than a value already seen
    newest = v.w[0];
  }
  stop = true;
  writer.join();
  EXPECT_EQ(torn, 0);
  EXPECT_GT(ok, 0);
  EXPECT_EQ(cell.load().w, cell.load().w);
}
