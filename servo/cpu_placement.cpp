#include "cpu_placement.h"

#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace isotouch::servo {

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
