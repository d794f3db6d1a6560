// cpu_placement.h - keeping a local peer process off the servo thread's CPU.
//
// A kernel without full preemption (PREEMPT_NONE / VOLUNTARY, the usual server and VM
// setting) lets a system call run to its end before a real-time thread woken on the same
// CPU gets it. A window on a CPU Vulkan device shows each frame through the X socket
// (Mesa's software presentation without DRI3 sends the whole image as one PutImage): the
// app's write and the X server's read of 3 MB each held the servo's CPU for 1.4-7.5 ms
// (ftrace: the servo woken on time, switched in only when the copy ended). Keeping the X
// server off the servo's CPU, and the app presenting from another CPU, removes both.
// And the calling thread's own placement: SCHED_FIFO and one CPU, for the servo thread and
// for benchmarks that time servo ticks under the servo's scheduling.
#pragma once
#include <sched.h>
#include <sys/types.h>

#include <string>
#include <vector>

namespace isotouch::servo {

/// The threads of one process kept off one CPU for this object's lifetime; the threads it
/// moved get their own CPU sets back when it is destroyed (threads the process started
/// meanwhile inherited the reduced set and keep it), and also when this process ends without
/// destroying it (a crash, SIGKILL, a second Ctrl+C): a guard, a small child process, is
/// told each thread's set through a socket whose other end only this process holds, and
/// blocks on it. The kernel closes that end whatever way this process ends; the guard then
/// gives the threads their sets back and exits.
class PeerOffCpu {
 public:
  PeerOffCpu() = default;
  ~PeerOffCpu();
  PeerOffCpu(const PeerOffCpu&) = delete;
  PeerOffCpu& operator=(const PeerOffCpu&) = delete;

  /// Forks the guard now (keep_off() does if none runs). Call it before a real-time thread
  /// starts: a fork write-protects the parent's pages, and that thread's next write to each
  /// would take a page fault (behind the fork's hold on the address space). Returns "" or
  /// why not (socketpair, fork).
  std::string start_guard();
  /// Moves every thread of process `pid` (its /proc/PID/task entries) off `cpu`. A thread
  /// whose set is only `cpu` is left where it is. Returns "" or why nothing was moved
  /// (no such process, permission: needs the same user or CAP_SYS_NICE). Nothing stays moved
  /// without the guard: if it cannot be started or told, the threads are given back at once
  /// and the reason returned.
  std::string keep_off(pid_t pid, int cpu);
  /// Gives the threads that still belong to the process their CPU sets back (also done by
  /// the destructor, which also ends the guard).
  void release();
  int threads_moved() const { return int(saved_.size()); }
  pid_t pid() const { return pid_; }
  /// The guard's process ID while one runs, else -1.
  pid_t guard_pid() const { return guard_pid_; }

  /// One thread's own CPU set, as the guard is told it.
  struct Saved {
    pid_t tid;      ///< 0: forget the threads told so far (they were given back)
    cpu_set_t set;
    char task[48];  ///< /proc/PID/task/TID (built here: the guard makes only system calls)
  };

 private:
  std::string tell_guard(const Saved& s);
  pid_t pid_ = -1;
  std::vector<Saved> saved_;
  pid_t guard_pid_ = -1;
  int guard_fd_ = -1;  // this process's end of the socket pair: closed when it ends, it wakes the guard
};

/// What make_thread_realtime got.
struct RealtimeSetup {
  bool fifo = false;  ///< SCHED_FIFO granted
  int cpu = -1;       ///< the CPU the thread is pinned to; -1: not pinned
  std::string note;   ///< "" or one line per thing the system did not allow, each naming `who`
};

/// Makes the calling thread real-time: SCHED_FIFO at `priority` (clamped to 1-99) if `fifo`,
/// then, if `pin`, pinned to `cpu`; `cpu` -1 is the last CPU the thread may run on (CPU 0
/// takes most interrupts and housekeeping), pinned only if SCHED_FIFO was granted (a normal
/// thread pinned to a busy CPU cannot move to an idle one). Refusals (no root,
/// CAP_SYS_NICE nor rtprio limit; a CPU not allowed) leave that part as it was and are
/// described in the note, which names the thread as `who`: they are not errors.
RealtimeSetup make_thread_realtime(const std::string& who, bool fifo, int priority, bool pin, int cpu);

/// The calling thread made real-time (make_thread_realtime with SCHED_FIFO and pinning) for
/// this object's lifetime; the destructor gives the thread back its scheduling policy,
/// priority and CPU set (as the kernel had them; if the policy cannot be set back, the
/// default one: never left at FIFO). Construct and destroy it on the same thread. A thread
/// under SCHED_DEADLINE is left as it is (said in the note).
class ScopedRealtime {
 public:
  explicit ScopedRealtime(const std::string& who, int priority = 80, int cpu = -1);
  ~ScopedRealtime();
  ScopedRealtime(const ScopedRealtime&) = delete;
  ScopedRealtime& operator=(const ScopedRealtime&) = delete;
  const RealtimeSetup& setup() const { return setup_; }

 private:
  RealtimeSetup setup_;
  int policy_ = SCHED_OTHER;
  sched_param param_{};
  cpu_set_t set_{};
  bool saved_ = false;
};

/// The calling thread kept off `cpu` for this object's lifetime: its CPU set without `cpu`,
/// when another CPU is left in it (else, or for `cpu` < 0, nothing changes). The destructor
/// gives the set back. For a thread that works beside a servo pinned to `cpu` (the edit
/// thread): there it would stop for the servo's spin and tick, most of every period at 4 kHz.
/// Construct and destroy it on the same thread.
class ScopedOffCpu {
 public:
  explicit ScopedOffCpu(int cpu);
  ~ScopedOffCpu();
  ScopedOffCpu(const ScopedOffCpu&) = delete;
  ScopedOffCpu& operator=(const ScopedOffCpu&) = delete;
  /// Whether the thread was moved off the CPU.
  bool moved() const { return moved_; }

 private:
  cpu_set_t set_{};
  bool moved_ = false;
};

/// The process at the other end of the connected Unix socket `fd` (SO_PEERCRED: the one
/// that listened), or -1 with the reason in `why` (not a socket, a TCP connection).
pid_t peer_pid(int fd, std::string& why);

/// The process name of `pid` (/proc/PID/comm), or "" if unknown.
std::string process_name(pid_t pid);

/// Whether a process of this name is an X server (Xorg, Xvfb, Xwayland, Xephyr, Xvnc...:
/// the name starts with 'X'). Under Xwayland the display socket may have been opened by the
/// Wayland compositor (mutter, kwin), which must not be moved.
bool is_x_server(const std::string& name);

}  // namespace isotouch::servo
