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
/// store() is wait-free; load() retries only while a store is in progress (a few ns). The
/// value lives in atomic words, so the cell is free of data races (TSan-clean, no fences).
/// Nothing allocates after construction.
template <class T>
class LatestValue {
  static_assert(std::is_trivially_copyable_v<T>, "LatestValue holds trivially copyable values");
  static constexpr std::size_t kWords = (sizeof(T) + 7) / 8;

 public:
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

  /// Any thread: the newest completely stored value.
  T load() const noexcept {
    std::array<std::uint64_t, kWords> w{};
    for (;;) {
      const std::uint64_t s0 = seq_.load(std::memory_order_acquire);
      if (s0 & 1) continue;
      // Acquire loads: the sequence re-read below cannot move above them.
      for (std::size_t i = 0; i < kWords; ++i) w[i] = words_[i].load(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) == s0) break;
    }
    T v;
    std::memcpy(static_cast<void*>(&v), w.data(), sizeof(T));  // trivially copyable
    return v;
  }

  /// How many values were stored (the initial one counts).
  std::uint64_t stores() const noexcept { return seq_.load(std::memory_order_acquire) / 2; }

 private:
  std::atomic<std::uint64_t> seq_{0};
  std::array<std::atomic<std::uint64_t>, kWords> words_{};
};

}  // namespace isotouch::servo
