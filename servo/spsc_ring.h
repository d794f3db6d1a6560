// spsc_ring.h - a bounded single-producer single-consumer queue, lock-free and preallocated.
//
// The servo thread hands data to other threads through these (brush requests to the edit
// thread, tick records to the recorder): push() on the servo side allocates nothing, takes
// no lock and makes no syscall; a full ring refuses the item (the caller counts it) rather
// than wait. One thread may push and one other thread may pop, at any time.
#pragma once
#include <atomic>
#include <cstddef>
#include <memory>
#include <new>
#include <stdexcept>
#include <type_traits>

#include "isotouch/servo/memory_range.h"

namespace isotouch::servo {

template <class T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "SpscRing holds plain data: copied, never constructed per push");

 public:
  /// @param capacity items the ring holds, rounded up to a power of two (>= 2).
  /// @throws std::invalid_argument if capacity is 0 or above 2^30.
  explicit SpscRing(std::size_t capacity) {
    if (capacity == 0 || capacity > (std::size_t(1) << 30))
      throw std::invalid_argument("SpscRing: capacity must be in [1, 2^30]");
    std::size_t n = 2;
    while (n < capacity) n <<= 1;
    mask_ = n - 1;
    items_ = std::make_unique<T[]>(n);  // value-initialised: every page touched now, not on the servo thread
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  std::size_t capacity() const { return mask_ + 1; }
  /// The items' storage, capacity() items (to lock it in memory with the servo's).
  MemoryRange storage() const { return {items_.get(), capacity() * sizeof(T)}; }

  /// Producer: false (and nothing stored) when the ring is full.
  bool push(const T& item) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ > mask_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ > mask_) return false;
    }
    items_[head & mask_] = item;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  /// Consumer: false when the ring is empty.
  bool pop(T& out) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return false;
    }
    out = items_[tail & mask_];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Items waiting (exact when called by either side with the other idle; a snapshot otherwise).
  std::size_t size() const noexcept {
    return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
  }

 private:
  std::unique_ptr<T[]> items_;
  std::size_t mask_ = 1;
  // Producer and consumer indices on their own cache lines, each side's cache of the other's.
  alignas(64) std::atomic<std::size_t> head_{0};
  std::size_t tail_cache_ = 0;
  alignas(64) std::atomic<std::size_t> tail_{0};
  std::size_t head_cache_ = 0;
};

}  // namespace isotouch::servo
