#include "isotouch/servo/exit_zero.h"

#include <sys/socket.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <memory>
#include <csignal>
#include <cstring>

namespace isotouch::servo {
namespace {

// A slot's state: free, being filled by its link, registered, or being sent by
// send_exit_zeros() (its link's destructor waits: the socket stays open, the bytes whole).
constexpr int kFree = 0, kFilling = 1, kUsed = 2, kSending = 3;

struct Slot {
  std::atomic<int> state{kFree};
  std::atomic<int> busy{0};  // the link's own send under way
  int fd = -1;
  std::size_t n = 0;
  std::uint8_t bytes[ExitZero::kMaxBytes] = {};
};
std::array<Slot, ExitZero::kSlots> g_slots;
std::atomic<bool> g_sealed{false};  // the last zeros are going out: the links send nothing more
static_assert(std::atomic<int>::is_always_lock_free && std::atomic<bool>::is_always_lock_free,
              "the signal handler may only touch lock-free atomics");

constexpr int kFatal[] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT};
struct sigaction g_previous[sizeof kFatal / sizeof kFatal[0]];
std::atomic<bool> g_installed{false};

std::int64_t mono_ns() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);  // async-signal-safe
  return std::int64_t(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

/// A fatal signal: the zeros first, then what was there before (a sanitizer's report, or the
/// default action: the core dump and exit status 128 + sig).
extern "C" void on_fatal_signal(int sig) {
  send_exit_zeros(2000);
  for (std::size_t i = 0; i < sizeof kFatal / sizeof kFatal[0]; ++i)
    if (kFatal[i] == sig) sigaction(sig, &g_previous[i], nullptr);
  raise(sig);
}

void install_fatal_handlers() {
  if (g_installed.exchange(true)) return;
  for (std::size_t i = 0; i < sizeof kFatal / sizeof kFatal[0]; ++i) {
    struct sigaction a {};
    a.sa_handler = on_fatal_signal;
    sigemptyset(&a.sa_mask);
    // SA_NODEFER: the handler re-raises with the previous action in place. SA_ONSTACK: on a
    // thread with an alternate stack (ensure_signal_stack) a stack overflow's SIGSEGV still
    // runs it.
    a.sa_flags = SA_NODEFER | SA_ONSTACK;
    sigaction(kFatal[i], &a, &g_previous[i]);
  }
}

/// The calling thread's alternate signal stack, freed when the thread ends (after it is taken
/// off: the kernel must not keep a pointer into freed memory).
struct SignalStack {
  std::unique_ptr<std::uint8_t[]> mem;
  ~SignalStack() {
    if (!mem) return;
    stack_t off{};
    off.ss_flags = SS_DISABLE;
    sigaltstack(&off, nullptr);
  }
};

}  // namespace

bool ensure_signal_stack() {
  thread_local SignalStack stack;
  if (stack.mem) return true;
  stack_t now{};
  if (sigaltstack(nullptr, &now) == 0 && !(now.ss_flags & SS_DISABLE)) return true;  // one set by others (a sanitizer)
  const std::size_t size = std::max<std::size_t>(SIGSTKSZ, 64 * 1024);
  auto mem = std::make_unique<std::uint8_t[]>(size);
  stack_t ss{};
  ss.ss_sp = mem.get();
  ss.ss_size = size;
  if (sigaltstack(&ss, nullptr) != 0) return false;
  stack.mem = std::move(mem);
  return true;
}

ExitZero::ExitZero(int fd, const std::uint8_t* bytes, std::size_t n) {
  if (n > kMaxBytes || fd < 0) return;
  for (int i = 0; i < kSlots; ++i) {
    int expect = kFree;
    Slot& s = g_slots[std::size_t(i)];
    if (!s.state.compare_exchange_strong(expect, kFilling)) continue;
    s.fd = fd;
    s.n = n;
    std::memcpy(s.bytes, bytes, n);
    s.busy.store(0);
    s.state.store(kUsed, std::memory_order_release);
    slot_ = i;
    break;
  }
  install_fatal_handlers();
  ensure_signal_stack();  // the thread that opens the link
}

ExitZero::~ExitZero() {
  if (slot_ < 0) return;
  Slot& s = g_slots[std::size_t(slot_)];
  for (int used = kUsed; !s.state.compare_exchange_weak(used, kFree, std::memory_order_acq_rel); used = kUsed) {
  }  // a zero being sent from this slot: wait until it is out
}

bool ExitZero::begin_send() {
  if (slot_ < 0) return !g_sealed.load();
  Slot& s = g_slots[std::size_t(slot_)];
  // Seen by send_exit_zeros() before it sends, or this sees the seal (both sequentially
  // consistent): the zero never goes out in the middle of this send, nor before it.
  s.busy.store(1);
  if (g_sealed.load()) {
    s.busy.store(0);
    return false;
  }
  return true;
}

void ExitZero::end_send() {
  if (slot_ >= 0) g_slots[std::size_t(slot_)].busy.store(0);
}

int send_exit_zeros(int wait_us) noexcept {
  g_sealed.store(true);
  int sent = 0;
  for (Slot& s : g_slots) {
    int used = kUsed;
    if (!s.state.compare_exchange_strong(used, kSending, std::memory_order_acq_rel)) continue;
    const std::int64_t give_up = mono_ns() + std::int64_t(wait_us) * 1000;
    while (s.busy.load() != 0 && mono_ns() < give_up) {
    }
    if (s.busy.load() != 0) {  // inside a send that does not end: the stream cannot take a zero
      s.state.store(kUsed, std::memory_order_release);
      continue;
    }
    std::size_t done = 0;
    while (done < s.n) {
      const ssize_t k = ::send(s.fd, s.bytes + done, s.n - done, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (k <= 0) break;
      done += std::size_t(k);
    }
    sent += done == s.n;
    s.state.store(kUsed, std::memory_order_release);
  }
  return sent;
}

}  // namespace isotouch::servo
