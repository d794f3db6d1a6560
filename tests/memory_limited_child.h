// memory_limited_child.h - run a load in a forked child whose address space is capped, and
// read back what it said: what the loader tests share to see a header that promises more
// than the file holds refused before anything is allocated (a load that tries the
// allocation gets std::bad_alloc instead).
#pragma once
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <exception>
#include <fstream>
#include <functional>
#include <string>

namespace isotouch::test {

/// The address space this process uses now [bytes] (/proc/self/statm).
inline std::uint64_t address_space_bytes() {
  std::uint64_t pages = 0;
  std::ifstream("/proc/self/statm") >> pages;
  return pages * std::uint64_t(::sysconf(_SC_PAGE_SIZE));
}

/// Runs `load` in a child with RLIMIT_AS = `limit` bytes: the message of what it threw
/// ("std::bad_alloc" for a failed allocation), "loaded" if it returned, "CRASH (status N)"
/// if the child died.
inline std::string message_under_memory_limit(std::uint64_t limit, const std::function<void()>& load) {
  int fds[2];
  if (::pipe(fds) != 0) return "pipe failed";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    const rlimit r{rlim_t(limit), rlim_t(limit)};
    ::setrlimit(RLIMIT_AS, &r);
    std::string msg = "loaded";
    try {
      load();
    } catch (const std::exception& e) {
      msg = e.what();
    }
    (void)!::write(fds[1], msg.data(), msg.size());
    ::_exit(0);
  }
  ::close(fds[1]);
  std::string out;
  char buf[4096];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) out.append(buf, std::size_t(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return out.empty() ? "CRASH (status " + std::to_string(status) + ")" : out;
}

}  // namespace isotouch::test
