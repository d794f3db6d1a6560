#include "isotouch/servo/cpu_placement.h"

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/wait.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace isotouch::servo {

namespace {
/// The last CPU in the calling thread's allowed set, or -1.
int last_allowed_cpu() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (pthread_getaffinity_np(pthread_self(), sizeof(set), &set) != 0) return -1;
  for (int c = CPU_SETSIZE - 1; c >= 0; --c)
    if (CPU_ISSET(c, &set)) return c;
  return -1;
}
}  // namespace

RealtimeSetup make_thread_realtime(const std::string& who, bool fifo, int priority, bool pin, int cpu) {
  RealtimeSetup r;
  if (fifo) {
    sched_param sp{};
    sp.sched_priority = std::clamp(priority, sched_get_priority_min(SCHED_FIFO), sched_get_priority_max(SCHED_FIFO));
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (rc == 0) r.fifo = true;
    else
      r.note += who + ": SCHED_FIFO priority " + std::to_string(sp.sched_priority) + " refused (" +
                std::strerror(rc) + "; needs root, CAP_SYS_NICE or an rtprio limit): running with the default "
                "scheduler, expect missed deadlines under load.\n";
  }
  if (pin && cpu < 0 && !r.fifo) {
    r.note += who + ": not pinned (without SCHED_FIFO a thread pinned to a busy CPU could not move to an idle "
                    "one).\n";
  } else if (pin) {
    const int c = cpu >= 0 ? cpu : last_allowed_cpu();
    cpu_set_t set;
    CPU_ZERO(&set);
    int rc = EINVAL;
    if (c >= 0 && c < CPU_SETSIZE) {
      CPU_SET(c, &set);
      rc = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
    }
    if (rc == 0) r.cpu = c;
    else
      r.note += who + ": pinning to CPU " + std::to_string(c) + " refused (" + std::strerror(rc) + "): not pinned.\n";
  }
  return r;
}

ScopedRealtime::ScopedRealtime(const std::string& who, int priority, int cpu) {
  // The kernel's view of this thread (tid 0), not glibc's cached policy.
  policy_ = sched_getscheduler(0);
  saved_ = policy_ >= 0 && sched_getparam(0, &param_) == 0 && sched_getaffinity(0, sizeof(set_), &set_) == 0;
  if (!saved_) {
    setup_.note = who + ": the thread's scheduling could not be read (" + std::strerror(errno) + "): left as it is.\n";
    return;
  }
  if (policy_ != SCHED_OTHER && policy_ != SCHED_BATCH && policy_ != SCHED_IDLE && policy_ != SCHED_FIFO &&
      policy_ != SCHED_RR) {
    saved_ = false;  // (SCHED_DEADLINE: not restorable by sched_setscheduler)
    setup_.note = who + ": scheduling policy " + std::to_string(policy_) + " left as it is.\n";
    return;
  }
  setup_ = make_thread_realtime(who, true, priority, true, cpu);
}

ScopedRealtime::~ScopedRealtime() {
  if (!saved_) return;
  sched_setaffinity(0, sizeof(set_), &set_);
  if (sched_setscheduler(0, policy_, &param_) != 0) {
    // Never left at FIFO: the default policy is always allowed.
    const sched_param other{};
    sched_setscheduler(0, SCHED_OTHER, &other);
  }
}

ScopedOffCpu::ScopedOffCpu(int cpu) {
  if (cpu < 0 || cpu >= CPU_SETSIZE || sched_getaffinity(0, sizeof(set_), &set_) != 0) return;
  if (!CPU_ISSET(cpu, &set_) || CPU_COUNT(&set_) < 2) return;
  cpu_set_t off = set_;
  CPU_CLR(cpu, &off);
  moved_ = sched_setaffinity(0, sizeof(off), &off) == 0;
}

ScopedOffCpu::~ScopedOffCpu() {
  if (moved_) sched_setaffinity(0, sizeof(set_), &set_);
}

namespace {
using Saved = PeerOffCpu::Saved;

// Async-signal-safe (the guard runs it in a child forked from a threaded process): system
// calls only. A thread that has exited is skipped (its ID may since name another process's
// thread).
void restore(const Saved* s, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i)
    if (access(s[i].task, F_OK) == 0) sched_setaffinity(s[i].tid, sizeof(cpu_set_t), &s[i].set);
}

constexpr std::size_t kGuardedMax = 1024;  // threads one guard keeps (an X server has a few)

/// The guard's life: out of the terminal's process group and deaf to the signals that end
/// the app (a Ctrl+C or a hangup reaches the whole foreground group), every inherited
/// descriptor but its end of the socket pair and stderr closed (a socket or device held open
/// would outlive the app); then it reads the threads' sets, one record per packet, until
/// the end of file (the app's end closed: the app is gone), gives back those it holds and
/// exits.
[[noreturn]] void guard_main(int rd) {
  setpgid(0, 0);
  struct sigaction ign {};
  ign.sa_handler = SIG_IGN;
  for (int sig : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE, SIGTSTP, SIGTTIN, SIGTTOU}) sigaction(sig, &ign, nullptr);
  for (int fd = 0; fd < 4096; ++fd)
    if (fd != rd && fd != STDERR_FILENO) close(fd);
  static Saved held[kGuardedMax];  // (the child's own copy: written by the guard only)
  std::size_t n = 0;
  Saved s;
  for (;;) {
    const ssize_t got = read(rd, &s, sizeof(s));
    if (got < 0 && errno == EINTR) continue;
    if (got != ssize_t(sizeof(s))) break;  // end of file: the app is gone
    if (s.tid == 0) n = 0;
    else if (n < kGuardedMax) held[n++] = s;
  }
  if (n > 0) {
    restore(held, n);
    static constexpr char kNote[] = "isotouch: the display server's CPU sets given back (the app ended without doing so)\n";
    if (write(STDERR_FILENO, kNote, sizeof(kNote) - 1) < 0) {
    }
  }
  _exit(0);
}
}  // namespace

std::string PeerOffCpu::start_guard() {
  if (guard_pid_ > 0) return "";
  // A socket pair, not a pipe: a send to a guard that was killed fails (MSG_NOSIGNAL)
  // instead of raising SIGPIPE, and each record arrives whole (SEQPACKET).
  int fds[2];
  if (socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, fds) != 0)
    return std::string("no guard process (socketpair: ") + std::strerror(errno) + ")";
  const pid_t child = fork();
  if (child == 0) guard_main(fds[0]);
  const int fork_errno = errno;
  close(fds[0]);
  if (child < 0) {
    close(fds[1]);
    return std::string("no guard process (fork: ") + std::strerror(fork_errno) + ")";
  }
  guard_fd_ = fds[1];
  guard_pid_ = child;
  return "";
}

std::string PeerOffCpu::tell_guard(const Saved& s) {
  ssize_t n;
  while ((n = send(guard_fd_, &s, sizeof(s), MSG_NOSIGNAL)) < 0 && errno == EINTR) {
  }
  if (n == ssize_t(sizeof(s))) return "";
  return std::string("the guard process ") + std::to_string(guard_pid_) + " cannot be told (" +
         (n < 0 ? std::strerror(errno) : "a short write") + ")";
}

std::string PeerOffCpu::keep_off(pid_t pid, int cpu) {
  release();
  if (cpu < 0 || cpu >= CPU_SETSIZE) return "CPU " + std::to_string(cpu) + " is not a CPU";
  std::error_code ec;
  const std::filesystem::path tasks = "/proc/" + std::to_string(pid) + "/task";
  std::filesystem::directory_iterator it(tasks, ec);
  if (ec) return "process " + std::to_string(pid) + ": " + ec.message();
  if (std::string e = start_guard(); !e.empty()) return "process " + std::to_string(pid) + " left where it is: " + e;
  pid_ = pid;
  std::string why;
  for (const auto& e : it) {
    const pid_t tid = pid_t(std::strtol(e.path().filename().c_str(), nullptr, 10));
    Saved s{tid, {}, {}};
    std::snprintf(s.task, sizeof(s.task), "/proc/%d/task/%d", int(pid), int(tid));
    if (sched_getaffinity(tid, sizeof(cpu_set_t), &s.set) != 0) {
      why = std::strerror(errno);
      continue;
    }
    cpu_set_t off = s.set;
    CPU_CLR(cpu, &off);
    if (CPU_COUNT(&off) == 0 || CPU_EQUAL(&off, &s.set)) continue;  // nowhere else / not on it
    if (saved_.size() >= kGuardedMax) break;
    // The guard knows the set before the thread leaves it.
    if (std::string told = tell_guard(s); !told.empty()) {
      release();
      return "process " + std::to_string(pid) + " left where it is: " + told;
    }
    if (sched_setaffinity(tid, sizeof(cpu_set_t), &off) != 0) {
      why = std::strerror(errno);
      continue;
    }
    saved_.push_back(s);
  }
  if (saved_.empty() && !why.empty()) return "process " + std::to_string(pid) + ": " + why;
  return "";
}

void PeerOffCpu::release() {
  restore(saved_.data(), saved_.size());
  saved_.clear();
  if (guard_fd_ >= 0) (void)tell_guard(Saved{0, {}, {}});  // nothing left to give back
}

PeerOffCpu::~PeerOffCpu() {
  release();
  if (guard_pid_ > 0) {
    kill(guard_pid_, SIGKILL);  // restored above: the guard has nothing left to do
    while (waitpid(guard_pid_, nullptr, 0) < 0 && errno == EINTR) {
    }
  }
  if (guard_fd_ >= 0) close(guard_fd_);
}

pid_t peer_pid(int fd, std::string& why) {
  ucred cred{};
  socklen_t len = sizeof(cred);
  if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0) {
    why = std::string("no local process at the other end of the socket (") + std::strerror(errno) + ")";
    return -1;
  }
  if (cred.pid <= 0) {
    why = "no local process at the other end of the socket (not a Unix socket: a remote display?)";
    return -1;
  }
  return cred.pid;
}

bool is_x_server(const std::string& name) { return !name.empty() && name[0] == 'X'; }

std::string process_name(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/comm");
  std::string name;
  std::getline(f, name);
  return name;
}

}  // namespace isotouch::servo
