// cpu_placement.h - keeping a local peer process off the servo thread's CPU.
//
// A kernel without full preemption (PREEMPT_NONE / VOLUNTARY, the usual server and VM
// setting) lets a system call run to its end before a real-time thread woken on the same
// CPU gets it. A window on a CPU Vulkan device shows each frame through the X socket
// (Mesa's software presentation without DRI3 sends the whole image as one PutImage): the
// app's write and the X server's read of 3 MB each held the servo's CPU for 1.3-7.5 ms
// (ftrace: the servo woken on time, switched in only when the copy ended). Keeping the X
// server off the servo's CPU, and the app presenting from another CPU, removes both.
#pragma once
#include <sched.h>
#include <sys/types.h>

#include <string>
#include <vector>

namespace isotouch::servo {

/// The threads of one process kept off one CPU for this object's lifetime; their own CPU
/// sets are given back when it is destroyed (threads started meanwhile keep theirs).
class PeerOffCpu {
 public:
  PeerOffCpu() = default;
  ~PeerOffCpu() { release(); }
  PeerOffCpu(PeerOffCpu&& o) noexcept : pid_(o.pid_), saved_(std::move(o.saved_)) { o.saved_.clear(); }
  PeerOffCpu& operator=(PeerOffCpu&& o) noexcept;
  PeerOffCpu(const PeerOffCpu&) = delete;
  PeerOffCpu& operator=(const PeerOffCpu&) = delete;

  /// Moves every thread of process `pid` (its /proc/PID/task entries) off `cpu`. A thread
  /// whose set is only `cpu` is left where it is. Returns "" or why nothing was moved
  /// (no such process, permission: needs the same user or CAP_SYS_NICE).
  std::string keep_off(pid_t pid, int cpu);
  /// The same for the process at the other end of the connected Unix socket `fd`
  /// (SO_PEERCRED): the X server of a window's display connection. A TCP display has no
  /// local peer: refused, with the reason.
  std::string keep_peer_off(int fd, int cpu);
  /// Gives the threads their CPU sets back (also done by the destructor).
  void release();
  int threads_moved() const { return int(saved_.size()); }
  pid_t pid() const { return pid_; }

 private:
  struct Saved {
    pid_t tid;
    cpu_set_t set;
  };
  pid_t pid_ = -1;
  std::vector<Saved> saved_;
};

/// The process name of `pid` (/proc/PID/comm), or "" if unknown.
std::string process_name(pid_t pid);

}  // namespace isotouch::servo
