// triple_buffer.h - the one lock-free publication point between engine and servo.
#pragma once
#include "isotouch/servo/core_names.h"
#include <atomic>
#include <cstdint>
#include <memory>

namespace isotouch::servo {

/// Single-producer / single-consumer triple buffer of immutable snapshots.
///
/// The engine thread calls publish() with a freshly built snapshot; the servo thread
/// calls acquire() at the top of each tick and gets the newest published one. acquire()
/// is wait-free (one atomic load, at most one exchange), never allocates and never
/// frees: an old snapshot is released on the publisher's thread when its slot is
/// reused. Nothing is copied: slots hold shared_ptr<const T>.
template <class T>
class TripleBuffer {
 public:
  /// Engine thread. Replaces the back slot and makes it the newest snapshot.
  void publish(std::shared_ptr<const T> snapshot) {
    slots_[back_] = std::move(snapshot);  // may free an old snapshot: publisher's thread
    const std::uint8_t prev = middle_.exchange(std::uint8_t(back_ | kFresh),
                                               std::memory_order_acq_rel);
    back_ = prev & kIndex;
    ever_published_.store(true, std::memory_order_release);
  }

  /// Any thread. True once publish() has been called: acquire() no longer returns nullptr.
  bool ever_published() const { return ever_published_.load(std::memory_order_acquire); }

  /// Servo thread. The newest published snapshot, or nullptr before the first publish.
  /// The reference stays valid until the next acquire() on the same thread.
  const T* acquire() {
    if (middle_.load(std::memory_order_acquire) & kFresh) {
      const std::uint8_t prev = middle_.exchange(front_, std::memory_order_acq_rel);
      front_ = prev & kIndex;
    }
    return slots_[front_].get();
  }

 private:
  static constexpr std::uint8_t kIndex = 0x3;
  static constexpr std::uint8_t kFresh = 0x4;
  std::shared_ptr<const T> slots_[3];
  std::uint8_t back_ = 0;                  // publisher-owned
  std::uint8_t front_ = 1;                 // consumer-owned
  std::atomic<std::uint8_t> middle_{2};    // shared; kFresh = not yet read
  std::atomic<bool> ever_published_{false};  // set by the first publish()
  static_assert(std::atomic<std::uint8_t>::is_always_lock_free);
};

}  // namespace isotouch::servo
