// SpscRing: the servo thread's lock-free queue to the edit thread and the recorder.
// Truth: a counter sequence pushed by one thread arrives whole and in order at another;
// run under ThreadSanitizer too (the tsan preset builds servo/).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "isotouch/servo/spsc_ring.h"

using isotouch::servo::SpscRing;

namespace {

struct Item {
  std::uint64_t seq = 0;
  double payload[5] = {};  // a few words, as a tick record: torn copies would show
};

TEST(SpscRing, CapacityIsAPowerOfTwoAndFullRefuses) {
  SpscRing<int> r(5);
  EXPECT_EQ(r.capacity(), 8u);
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(r.push(i)) << i;
  EXPECT_FALSE(r.push(99));  // full: refused, not overwritten
  EXPECT_EQ(r.size(), 8u);
  int v = -1;
  for (int i = 0; i < 8; ++i) {
    ASSERT_TRUE(r.pop(v));
    EXPECT_EQ(v, i);
  }
  EXPECT_FALSE(r.pop(v));
  EXPECT_TRUE(r.push(8));  // wraps
  ASSERT_TRUE(r.pop(v));
  EXPECT_EQ(v, 8);
}

TEST(SpscRing, RefusesABadCapacity) {
  EXPECT_THROW(SpscRing<int>(0), std::invalid_argument);
  EXPECT_THROW(SpscRing<int>((std::size_t(1) << 30) + 1), std::invalid_argument);
}

TEST(SpscRing, TwoThreadsPassEveryItemInOrder) {
  constexpr std::uint64_t kN = 2'000'000;
  SpscRing<Item> r(64);  // small: the producer meets a full ring often
  std::atomic<long> refused{0};
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kN;) {
      Item it;
      it.seq = i;
      for (double& p : it.payload) p = double(i);
      if (r.push(it)) {
        ++i;
      } else {
        refused.fetch_add(1, std::memory_order_relaxed);
      }
    }
  });
  std::uint64_t next = 0, bad = 0;
  Item got;
  while (next < kN) {
    if (!r.pop(got)) continue;
    if (got.seq != next) ++bad;
    for (double p : got.payload)
      if (p != double(got.seq)) ++bad;
    next = got.seq + 1;
  }
  producer.join();
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(next, kN);
  EXPECT_FALSE(r.pop(got));
}

}  // namespace
