#include "isotouch/session/stop_signal.h"

#include <fcntl.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>

#include <atomic>
#include <memory>

#include "isotouch/servo/exit_zero.h"
#include <mutex>
#include <vector>

namespace isotouch::session {
namespace {

std::atomic<int> g_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the handler may only touch a lock-free atomic");

/// What a second signal writes before the process ends; built before, read by the handler.
struct LastWords {
  std::string path, temp, on_sigint, on_sigterm;
};
std::atomic<const LastWords*> g_last_words{nullptr};
// Every LastWords ever set stays alive: a handler on another thread may still read one that
// was replaced (a few hundred bytes per run).
std::mutex g_kept_mu;
std::vector<std::unique_ptr<const LastWords>> g_kept;

// Async-signal-safe: open, write, close, rename only.
void write_last_words(int sig) {
  const LastWords* w = g_last_words.load();
  if (w == nullptr) return;
  const std::string& text = sig == SIGTERM ? w->on_sigterm : w->on_sigint;
  const int fd = ::open(w->temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return;
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n <= 0) break;
    done += std::size_t(n);
  }
  const bool whole = ::close(fd) == 0 && done == text.size();
  if (!whole || ::rename(w->temp.c_str(), w->path.c_str()) != 0) ::unlink(w->temp.c_str());
}

extern "C" void on_stop_signal(int sig) {
  int expected = 0;
  if (!g_signal.compare_exchange_strong(expected, sig)) {
    write_last_words(sig);
    servo::send_exit_zeros(2000);  // the links' peers keep no force (exit_zero.h)
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

void set_last_words(const std::string& path, const std::string& on_sigint, const std::string& on_sigterm) {
  auto w = std::make_unique<const LastWords>(
      LastWords{path, path + ".last-words-" + std::to_string(::getpid()), on_sigint, on_sigterm});
  const std::lock_guard<std::mutex> lock(g_kept_mu);
  g_last_words.store(w.get());
  g_kept.push_back(std::move(w));
}

void end_process_now(int sig) {
  write_last_words(sig);
  servo::send_exit_zeros(2000);
  std::signal(sig, SIG_DFL);
  std::raise(sig);
  std::_Exit(128 + sig);  // the signal was blocked or ignored: the same status
}

void clear_last_words() { g_last_words.store(nullptr); }

int stop_signal() { return g_signal.load(std::memory_order_relaxed); }

void throw_if_stop_requested(const std::string& stage) {
  if (const int s = stop_signal()) throw Interrupted(s, stage);
}

void request_stop_for_test(int sig) { g_signal.store(sig, std::memory_order_relaxed); }

}  // namespace isotouch::session
