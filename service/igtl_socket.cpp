#include "isotouch/service/igtl_socket.h"

#include <arpa/inet.h>
#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdexcept>
#include <thread>
#include <sys/socket.h>
#include <unistd.h>

namespace isotouch::service {
namespace {

/// Waits up to `ms` for `events` on `fd`: >0 ready, 0 timed out, <0 error.
int wait_for(int fd, short events, int ms) {
  pollfd p{fd, events, 0};
  for (;;) {
    const int r = ::poll(&p, 1, ms);
    if (r < 0 && errno == EINTR) continue;
    return r;
  }
}

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

Listener::Listener(const std::string& host, int port) {
  fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(std::uint16_t(port));
  const std::string where = host + ":" + std::to_string(port);
  if (port < 0 || port > 65535 || ::inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1) {
    ::close(fd_);
    throw std::runtime_error("listen on " + where + ": not an IPv4 address and port");
  }
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd_, 16) != 0) {
    const std::string e = std::strerror(errno);
    ::close(fd_);
    throw std::runtime_error("listen on " + where + ": " + e);
  }
  socklen_t len = sizeof a;
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
  port_ = ntohs(a.sin_port);
}

Listener::~Listener() { ::close(fd_); }

int Listener::accept(int timeout_ms) {
  if (wait_for(fd_, POLLIN, timeout_ms) <= 0) return -1;
  const int c = ::accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
  if (c >= 0) {
    const int one = 1;
    ::setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  }
  return c;
}

int connect_tcp(const std::string& host, int port, int timeout_ms) {
  const std::string where = host + ":" + std::to_string(port);
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (port < 1 || port > 65535 || ::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found) != 0 || !found)
    throw std::runtime_error("connect to " + where + ": not a host and port");
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  const int r = fd < 0 ? -1 : ::connect(fd, found->ai_addr, found->ai_addrlen);
  ::freeaddrinfo(found);
  int err = r == 0 ? 0 : errno;
  if (r != 0 && err == EINPROGRESS) {
    err = wait_for(fd, POLLOUT, timeout_ms) > 0 ? 0 : ETIMEDOUT;
    socklen_t len = sizeof err;
    if (err == 0) ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &len);
  }
  if (err != 0) {
    if (fd >= 0) ::close(fd);
    throw std::runtime_error("connect to " + where + ": " + std::strerror(err));
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);  // reads poll with deadlines; sends use MSG_DONTWAIT
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  return fd;
}

Connection::Connection(int fd, int receive_timeout_ms, int message_timeout_ms, const std::atomic<bool>* stop)
    : fd_(fd), timeout_ms_(receive_timeout_ms), message_timeout_ms_(message_timeout_ms), stop_(stop),
      last_in_ns_(now_ns()) {}

Connection::~Connection() { ::close(fd_); }

std::int64_t Connection::quiet_ms() const { return (now_ns() - last_in_ns_.load()) / 1000000; }

void Connection::shutdown() {
  alive_ = false;
  ::shutdown(fd_, SHUT_RDWR);
}

std::size_t Connection::read(void* dst, std::size_t n, bool first) {
  using Clock = std::chrono::steady_clock;
  auto* p = static_cast<std::uint8_t*>(dst);
  std::size_t got = 0;
  int waited_ms = 0;
  auto message_ms_left = [&] {
    return message_timeout_ms_ - int(std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - message_start_).count());
  };
  while (got < n) {
    const bool between = first && got == 0;  // waiting for a new message: no deadline
    if (!between && message_ms_left() <= 0) {
      why_ = std::to_string(got) + " of " + std::to_string(n) + " bytes arrived, the message not whole after " +
             std::to_string(message_timeout_ms_) + " ms";
      break;
    }
    const int slice = between ? 100 : std::max(1, std::min(100, message_ms_left()));
    const int r = wait_for(fd_, POLLIN, slice);
    if (r < 0) {
      why_ = std::string("poll: ") + std::strerror(errno);
      break;
    }
    if (r == 0) {
      if (stop_ && stop_->load()) {
        why_ = "the server is stopping";
        return between ? 0 : got;
      }
      waited_ms += slice;
      if (!between && waited_ms >= timeout_ms_) {
        why_ = std::to_string(got) + " of " + std::to_string(n) + " bytes arrived, then nothing for " +
               std::to_string(timeout_ms_) + " ms";
        break;
      }
      continue;
    }
    const ssize_t k = ::recv(fd_, p + got, n - got, 0);
    if (k == 0) {
      why_ = "the connection closed after " + std::to_string(got) + " of " + std::to_string(n) + " bytes";
      break;
    }
    if (k < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      why_ = std::string("recv: ") + std::strerror(errno);
      break;
    }
    if (between) message_start_ = Clock::now();  // the message's clock starts at its first byte
    last_in_ns_ = now_ns();
    got += std::size_t(k);
    waited_ms = 0;
  }
  return got;
}

Sent Connection::try_send(const void* data, std::size_t n, std::int64_t busy_wait_ns) {
  // Another send under way: tried again every 10 us until busy_wait_ns has passed (not a
  // timed mutex: ThreadSanitizer cannot follow its clocked lock), then dropped.
  std::unique_lock<std::mutex> lock(send_mu_, std::defer_lock);
  const auto until = std::chrono::steady_clock::now() + std::chrono::nanoseconds(busy_wait_ns);
  while (!lock.try_lock()) {
    if (std::chrono::steady_clock::now() >= until) return Sent::kBusy;
    std::this_thread::sleep_for(std::chrono::microseconds(10));
  }
  if (!alive_) return Sent::kDead;
  SendFence* fence = fence_.load();
  if (fence && !fence->begin_send()) return Sent::kDead;  // the process's last message went out
  struct EndSend {
    SendFence* f;
    ~EndSend() {
      if (f) f->end_send();
    }
  } end_send{fence};
  const ssize_t k = ::send(fd_, data, n, MSG_NOSIGNAL | MSG_DONTWAIT);
  if (k < 0 && (errno == EAGAIN || errno == EINTR)) return Sent::kFull;  // not reading: dropped, the connection kept
  if (k == ssize_t(n)) return Sent::kSent;
  alive_ = false;  // gone, or cut mid-message: the stream cannot go on
  ::shutdown(fd_, SHUT_RDWR);
  return Sent::kDead;
}

bool Connection::send(const void* data, std::size_t n, bool droppable) {
  if (droppable) return try_send(data, n) == Sent::kSent;
  std::lock_guard<std::mutex> lock(send_mu_);
  SendFence* fence = fence_.load();
  if (fence && !fence->begin_send()) return false;  // the process's last message went out
  struct EndSend {
    SendFence* f;
    ~EndSend() {
      if (f) f->end_send();
    }
  } end_send{fence};
  const auto* p = static_cast<const std::uint8_t*>(data);
  std::size_t sent = 0;
  // One deadline for the whole message: the receive timeout, plus 0.1 s per MB it holds.
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms_) +
                     std::chrono::microseconds(std::int64_t(n / 10));
  while (alive_ && sent < n) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now()).count();
    if (left <= 0 || wait_for(fd_, POLLOUT, int(std::min<std::int64_t>(left, 1 << 30))) <= 0) break;
    const ssize_t k = ::send(fd_, p + sent, n - sent, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (k < 0 && (errno == EINTR || errno == EAGAIN)) continue;
    if (k <= 0) break;
    sent += std::size_t(k);
  }
  if (sent < n && alive_.exchange(false)) ::shutdown(fd_, SHUT_RDWR);  // dropped: its reader ends too
  return sent == n;
}

}  // namespace isotouch::service
