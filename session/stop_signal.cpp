#include "stop_signal.h"

#include <csignal>

#include <atomic>

namespace isotouch::session {
namespace {

std::atomic<int> g_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the handler may only touch a lock-free atomic");

extern "C" void on_stop_signal(int sig) {
  int expected = 0;
  if (!g_signal.compare_exchange_strong(expected, sig)) {
    std::signal(sig, SIG_DFL);  // asked twice: stop now
    std::raise(sig);
  }
}

std::string signal_name(int sig) {
  switch (sig) {
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
    case SIGQUIT: return "SIGQUIT";
    default: return "SIGINT";
  }
}

}  // namespace

Interrupted::Interrupted(int sig, std::string where)
    : std::runtime_error("interrupted by " + signal_name(sig) + " during " + where),
      signal(sig),
      stage(std::move(where)) {}

void install_stop_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  // No SA_RESTART: a call blocked on a FIFO without a reader (or the like) returns EINTR
  // and the command stops with a named error instead of swallowing the first Ctrl+C.
  sa.sa_flags = 0;
  // A closed terminal (SIGHUP) and Ctrl+\ (SIGQUIT) stop as cleanly as Ctrl+C: whatever
  // the command changed outside itself (a recording, the display server's CPUs) is put right.
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) sigaction(sig, &sa, nullptr);
  // A stream output whose reader went away (| head) fails with EPIPE, named, instead of
  // ending the process silently.
  std::signal(SIGPIPE, SIG_IGN);
}

int stop_signal() { return g_signal.load(std::memory_order_relaxed); }

void throw_if_stop_requested(const std::string& stage) {
  if (const int s = stop_signal()) throw Interrupted(s, stage);
}

void request_stop_for_test(int sig) { g_signal.store(sig, std::memory_order_relaxed); }

}  // namespace isotouch::session
