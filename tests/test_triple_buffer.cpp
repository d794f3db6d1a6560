// The lock-free publication point between engine and servo.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "isotouch/servo/triple_buffer.h"

using isotouch::servo::TripleBuffer;

TEST(TripleBuffer, EmptyUntilFirstPublish) {
  TripleBuffer<int> b;
  EXPECT_EQ(b.acquire(), nullptr);
  b.publish(std::make_shared<const int>(7));
  ASSERT_NE(b.acquire(), nullptr);
  EXPECT_EQ(*b.acquire(), 7);
}

TEST(TripleBuffer, ReaderSeesNewestAndKeepsItUntilNextPublish) {
  TripleBuffer<int> b;
  for (int i = 0; i < 5; ++i) b.publish(std::make_shared<const int>(i));
  EXPECT_EQ(*b.acquire(), 4);
  EXPECT_EQ(*b.acquire(), 4);
  b.publish(std::make_shared<const int>(9));
  EXPECT_EQ(*b.acquire(), 9);
}

TEST(TripleBuffer, ConcurrentReaderNeverSeesATornOrOlderSnapshot) {
  struct Snap {
    long a, b;  // always equal in a whole snapshot
  };
  TripleBuffer<Snap> buf;
  buf.publish(std::make_shared<const Snap>(Snap{0, 0}));
  std::atomic<bool> stop{false}, reading{false};
  std::thread writer([&] {
    // Publishing starts once the reader runs (on a loaded machine the writer could finish
    // all of it before the reader's first read).
    while (!reading.load()) std::this_thread::yield();
    for (long i = 1; i <= 200000; ++i) buf.publish(std::make_shared<const Snap>(Snap{i, i}));
    stop = true;
  });
  long last = 0, reads = 0;
  reading = true;
  do {
    const Snap* s = buf.acquire();
    ASSERT_EQ(s->a, s->b);
    ASSERT_GE(s->a, last);  // versions never go back
    last = s->a;
    ++reads;
  } while (!stop.load());
  writer.join();
  EXPECT_EQ(buf.acquire()->a, 200000);
  EXPECT_GT(reads, 0);
}
