// latest_value.h - a single-writer latest-value cell (seqlock) for small trivially copyable
// values: the device reader hands the newest report to the servo without locks.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace isotouch::servo {

/// One writer thread store()s, any number of readers load() the newest complete value.
/// store() is wait-free. load(T&) is bounded: it retries at most kMaxTries times while a
/// store is in progress (a few ns each, unless the writer was preempted inside one), then
/// keeps the caller's last value and counts the miss: the servo thread never waits on an
/// unpinned writer. load() retries until it succeeds, for threads that may wait. The value
/// lives in atomic words, so the cell is free of data races (TSan-clean, no fences).
/// Nothing allocates after construction.
template <class T>
class LatestValue {
  static_assert(std::is_trivially_copyable_v<T>, "LatestValue holds trivially copyable values");
  static constexpr std::size_t kWords = (sizeof(T) + 7) / 8;

 public:
  /// Attempts of load(T&) before it gives up (about a microsecond of retries).
  static constexpr int kMaxTries = 64;

  explicit LatestValue(const T& initial = T{}) { store(initial); }

  /// Writer thread only.
  void store(const T& v) noexcept {
    std::array<std::uint64_t, kWords> w{};
    std::memcpy(w.data(), &v, sizeof(T));
    const std::uint64_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);  // odd: a store is in progress
    // Release stores: a reader that sees any new word also sees the odd sequence (no fence,
    // which ThreadSanitizer cannot follow; plain moves on x86).
    for (std::size_t i = 0; i < kWords; ++i) words_[i].store(w[i], std::memory_order_release);
    seq_.store(s + 2, std::memory_order_release);
  }

  /// Any thread, never waiting long: the newest completely stored value into `last`; false
  /// if a store stayed in progress for kMaxTries attempts (`last` is left as it was, the
  /// caller's last value, and misses() counts it).
  bool load(T& last) const noexcept {
    for (int i = 0; i < kMaxTries; ++i)
      if (try_load(last)) return true;
    misses_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }

  /// Any thread that may wait: the newest completely stored value.
  T load() const noexcept {
    T v;
    while (!try_load(v)) {
    }
    return v;
  }

  /// How many times load(T&) gave up and left the caller's last value.
  std::uint64_t misses() const noexcept { return misses_.load(std::memory_order_relaxed); }

  /// How many values were stored (the initial one counts).
  std::uint64_t stores() const noexcept { return seq_.load(std::memory_order_acquire) / 2; }

 private:
  friend struct LatestValueTest;  // holds a store in progress, as a preempted writer would

  /// One attempt: false if a store was in progress (`out` unchanged).
  bool try_load(T& out) const noexcept {
    std::array<std::uint64_t, kWords> w{};
    const std::uint64_t s0 = seq_.load(std::memory_order_acquire);
    if (s0 & 1) return false;
    // Acquire loads: the sequence re-read below cannot move above them.
    for (std::size_t i = 0; i < kWords; ++i) w[i] = words_[i].load(std::memory_order_acquire);
    if (seq_.load(std::memory_order_relaxed) != s0) return false;
    std::memcpy(static_cast<void*>(&out), w.data(), sizeof(T));  // trivially copyable
    return true;
  }

  std::atomic<std::uint64_t> seq_{0};
  std::array<std::atomic<std::uint64_t>, kWords> words_{};
  mutable std::atomic<std::uint64_t> misses_{0};
};

}  // namespace isotouch::servo
