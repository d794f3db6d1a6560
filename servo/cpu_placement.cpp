#include "cpu_placement.h"

#include <sys/socket.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace isotouch::servo {

PeerOffCpu& PeerOffCpu::operator=(PeerOffCpu&& o) noexcept {
  if (this != &o) {
    release();
    pid_ = o.pid_;
    saved_ = std::move(o.saved_);
    o.saved_.clear();
  }
  return *this;
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

std::string PeerOffCpu::keep_peer_off(int fd, int cpu) {
  ucred cred{};
  socklen_t len = sizeof(cred);
  if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0 || cred.pid <= 0)
    return std::string("no local process at the other end of the socket (") +
           (errno ? std::strerror(errno) : "no peer") + ")";
  return keep_off(cred.pid, cpu);
}

void PeerOffCpu::release() {
  for (const Saved& s : saved_) sched_setaffinity(s.tid, sizeof(cpu_set_t), &s.set);  // gone: nothing to do
  saved_.clear();
}

std::string process_name(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/comm");
  std::string name;
  std::getline(f, name);
  return name;
}

}  // namespace isotouch::servo
