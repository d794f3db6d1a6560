#include "cpu_placement.h"

#include <pthread.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
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

std::string PeerOffCpu::keep_off(pid_t pid, int cpu) {
  release();
  if (cpu < 0 || cpu >= CPU_SETSIZE) return "CPU " + std::to_string(cpu) + " is not a CPU";
  std::error_code ec;
  const std::filesystem::path tasks = "/proc/" + std::to_string(pid) + "/task";
  std::filesystem::directory_iterator it(tasks, ec);
  if (ec) return "process " + std::to_string(pid) + ": " + ec.message();
  std::string why;
  for (const auto& e : it) {
    const pid_t tid = pid_t(std::strtol(e.path().filename().c_str(), nullptr, 10));
    Saved s{tid, {}};
    if (sched_getaffinity(tid, sizeof(cpu_set_t), &s.set) != 0) {
      why = std::strerror(errno);
      continue;
    }
    cpu_set_t off = s.set;
    CPU_CLR(cpu, &off);
    if (CPU_COUNT(&off) == 0 || CPU_EQUAL(&off, &s.set)) continue;  // nowhere else / not on it
    if (sched_setaffinity(tid, sizeof(cpu_set_t), &off) != 0) {
      why = std::strerror(errno);
      continue;
    }
    saved_.push_back(s);
  }
  pid_ = pid;
  if (saved_.empty() && !why.empty()) return "process " + std::to_string(pid) + ": " + why;
  return "";
}

void PeerOffCpu::release() {
  // A thread that has exited is skipped (its ID may since name another process's thread).
  const std::string tasks = "/proc/" + std::to_string(pid_) + "/task/";
  for (const Saved& s : saved_)
    if (access((tasks + std::to_string(s.tid)).c_str(), F_OK) == 0)
      sched_setaffinity(s.tid, sizeof(cpu_set_t), &s.set);
  saved_.clear();
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
