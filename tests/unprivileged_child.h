// unprivileged_child.h - run a check in a forked child that has given up root (uid and gid
// 65534, no real-time priority limit, so no CAP_SYS_NICE either): what the scheduling tests
// share to see a refusal that root would not get.
#pragma once
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <functional>

namespace isotouch::test {

/// Exit code of `check` run in a child without root; kCouldNotDrop where the child could not
/// give root up (a user namespace without uid 65534), kThrew where `check` threw (the child
/// never returns into the test runner), -1 where it did not exit normally. Call it from a
/// test running as root, before the process starts threads of its own.
constexpr int kCouldNotDrop = 10, kThrew = 11;
inline int run_unprivileged(const std::function<int()>& check) {
  const pid_t pid = fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    struct rlimit no_rt{0, 0};
    if (setrlimit(RLIMIT_RTPRIO, &no_rt) != 0 || setgid(65534) != 0 || setuid(65534) != 0) _exit(kCouldNotDrop);
    int code = kThrew;
    try {
      code = check();
    } catch (...) {
    }
    _exit(code);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

}  // namespace isotouch::test
