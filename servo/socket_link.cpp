#include "isotouch/servo/socket_link.h"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace isotouch::servo {

std::string SocketLink::open() {
  close();
  sockaddr_un addr{};
  if (path_.size() >= sizeof(addr.sun_path)) return "socket path longer than " + std::to_string(sizeof(addr.sun_path) - 1) + " bytes";
  addr.sun_family = AF_UNIX;
  std::memcpy(addr.sun_path, path_.c_str(), path_.size() + 1);
  fd_ = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd_ < 0) return std::string("socket: ") + std::strerror(errno);
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    const std::string e = std::string("cannot connect (") + std::strerror(errno) + "; is isotouch-devemu running?)";
    close();
    return e;
  }
  return {};
}

void SocketLink::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

int SocketLink::read(std::span<std::uint8_t> buf, int timeout_ms) {
  if (fd_ < 0) return -1;
  pollfd p{fd_, POLLIN, 0};
  const int r = ::poll(&p, 1, timeout_ms);
  if (r == 0) return 0;
  if (r < 0) return errno == EINTR ? 0 : -1;
  const ssize_t n = ::recv(fd_, buf.data(), buf.size(), MSG_DONTWAIT);
  if (n > 0) return int(n);
  if (n < 0 && (errno == EAGAIN || errno == EINTR)) return 0;
  return -1;  // 0 bytes: the emulator closed the connection
}

bool SocketLink::wait_readable(int timeout_ms) {
  if (fd_ < 0) return true;  // down: read() says so
  pollfd p{fd_, POLLIN, 0};
  return ::poll(&p, 1, timeout_ms) != 0;  // ready, hung up or an error: read() tells
}

bool SocketLink::write(std::span<const std::uint8_t> report) {
  if (fd_ < 0) return false;
  return ::send(fd_, report.data(), report.size(), MSG_NOSIGNAL | MSG_DONTWAIT) == ssize_t(report.size());
}

int SocketLink::get_feature(std::uint8_t id, std::span<std::uint8_t> buf) {
  if (!write(std::span(&id, 1))) return -1;
  for (int i = 0; i < 200; ++i) {  // up to ~1 s
    const int n = read(buf, 5);
    if (n < 0) return -1;
    if (n > 0 && buf[0] == id) return n;
  }
  return -1;
}

}  // namespace isotouch::servo
