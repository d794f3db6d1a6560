// exit_zero.h - the zero force a link's peer must get however the process ends. A peer that
// applies the last force it received with no age check (PLUS over OpenIGTLink: its
// OpenHaptics device holds the latest Force TRANSFORM) keeps a contact force on after
// isotouch is gone unless the last message it got is a zero. Normal, error and stop-signal
// exits send it from the link's own writer; this covers the exits that skip it: a servo
// thread stuck in the renderer (end_process_servo_stuck's _Exit), a second stop signal (the
// signal's default action) and a fatal signal (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT).
#pragma once
#include <cstddef>
#include <cstdint>

namespace isotouch::servo {

/// One link's pre-packed zero-force message, registered while the link is open (RAII). The
/// link's own sends go between begin_send() and end_send(), so the zero is never sent into
/// the middle of one of its messages, and nothing of its own follows the zero.
class ExitZero {
 public:
  static constexpr std::size_t kMaxBytes = 256;  ///< the longest message a slot holds
  static constexpr int kSlots = 8;               ///< links registered at once

  /// Registers socket `fd` with `bytes` (copied), and installs the fatal-signal handlers
  /// (once per process). A link beyond kSlots, or a message longer than kMaxBytes, is not
  /// registered (registered() false): the caller says so.
  ExitZero(int fd, const std::uint8_t* bytes, std::size_t n);
  ~ExitZero();  ///< unregisters (the link's own writer sent its zero)
  ExitZero(const ExitZero&) = delete;
  ExitZero& operator=(const ExitZero&) = delete;
  bool registered() const { return slot_ >= 0; }

  /// Before a send of the link's own: false once the process's last zero is being sent (send
  /// nothing then). Pair every true with end_send().
  bool begin_send();
  void end_send();

 private:
  int slot_ = -1;
};

/// Gives the calling thread an alternate signal stack (once; kept until the thread ends), so
/// that a stack overflow's SIGSEGV on it still runs the fatal-signal handler that sends the
/// zeros. Allocates: call it when a thread starts, never on the servo's tick. A thread that
/// already has one (a sanitizer's) keeps it. False if the system refused it.
bool ensure_signal_stack();

/// Sends every registered link its zero (send(2), MSG_NOSIGNAL | MSG_DONTWAIT), each after
/// waiting up to `wait_us` for a send of its own under way to finish (a link whose send does
/// not finish, such as one the crashing thread was inside, is skipped). From then on the
/// links send nothing of their own. Async-signal-safe. Returns the zeros sent.
int send_exit_zeros(int wait_us) noexcept;

}  // namespace isotouch::servo
