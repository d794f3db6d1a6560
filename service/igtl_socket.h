// igtl_socket.h - TCP connections for OpenIGTLink, owned here rather than by the library's
// igtl::Socket for its two traps: its Send raises SIGPIPE on a dead peer (which kills the
// process), and its blocking Receive of a truncated body waits forever. Here every send uses
// MSG_NOSIGNAL and a send deadline, and every read inside a message has a deadline.
// Part of isotouch::service.
#pragma once
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "isotouch/service/igtl_message.h"

namespace isotouch::service {

/// A listening TCP socket.
class Listener {
 public:
  /// Binds `host` ("127.0.0.1", "0.0.0.0") and `port` (0: any free port) and listens.
  /// @throws std::runtime_error naming the address and the system's reason.
  Listener(const std::string& host, int port);
  ~Listener();
  Listener(const Listener&) = delete;
  Listener& operator=(const Listener&) = delete;
  int port() const { return port_; }
  /// A connected socket, or -1 when none arrived within `timeout_ms`.
  int accept(int timeout_ms);

 private:
  int fd_ = -1;
  int port_ = 0;
};

/// A TCP connection to `host` (an IPv4 address or a name) and `port`, TCP_NODELAY set,
/// within `timeout_ms`. @throws std::runtime_error naming the address and the reason.
int connect_tcp(const std::string& host, int port, int timeout_ms);

/// One connected client: reads with deadlines, sends that never raise SIGPIPE.
/// Called around each of a connection's sends, under its send lock: begin_send() false
/// refuses the send (the process's last message to the peer already went out), and the last
/// message is never put into the middle of one (servo/exit_zero.h).
class SendFence {
 public:
  virtual ~SendFence() = default;
  virtual bool begin_send() = 0;
  virtual void end_send() = 0;
};

/// What a droppable send did (Connection::try_send).
enum class Sent {
  kSent,  ///< all of it went out
  kFull,  ///< the peer's buffers are full (it is not reading): dropped, the connection kept
  kBusy,  ///< another send to this peer was under way: dropped, the connection kept
  kDead,  ///< the connection is gone or was cut now (the peer gone, or only part fitted)
};

class Connection final : public ByteSource {
 public:
  /// Owns `fd`. `receive_timeout_ms`: the longest wait for the next byte inside a message;
  /// `message_timeout_ms`: the longest a whole message may take from its first byte (a
  /// client dripping bytes is dropped there); `stop`: ends the wait for a new message
  /// (read() then returns 0).
  Connection(int fd, int receive_timeout_ms, int message_timeout_ms, const std::atomic<bool>* stop);
  ~Connection() override;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  std::size_t read(void* dst, std::size_t n, bool first) override;
  std::string why() const override { return why_; }
  /// Sends all `n` bytes (any thread; sends are serialised) within one deadline for the whole
  /// message: the receive timeout plus 0.1 s per MB (a peer that takes a byte now and then
  /// does not stretch it). False, and the connection cut (shut down: its reader ends), when the
  /// peer is gone or does not take the message in time.
  bool send(const void* data, std::size_t n, bool droppable);
  bool send(const std::vector<std::uint8_t>& bytes) { return send(bytes.data(), bytes.size(), false); }
  /// As send(), but never waits: when the peer's receive buffer is full (a client that never
  /// reads, like a tracker) or another send is under way, the bytes are dropped and false
  /// returned, the connection kept; when only part of them fit, the stream is cut mid-message
  /// and the connection is marked dead.
  bool send_droppable(const std::vector<std::uint8_t>& bytes) { return send(bytes.data(), bytes.size(), true); }
  /// As send_droppable(), saying why a send was dropped. `busy_wait_ns` > 0: another send
  /// under way is waited for that long before kBusy (never the peer's buffers: kFull at once).
  Sent try_send(const void* data, std::size_t n, std::int64_t busy_wait_ns = 0);
  Sent try_send(const std::vector<std::uint8_t>& bytes, std::int64_t busy_wait_ns = 0) {
    return try_send(bytes.data(), bytes.size(), busy_wait_ns);
  }
  bool alive() const { return alive_.load(); }
  /// How long the peer has sent no byte [ms]: since the last byte read() received, or since
  /// the connection was made when none came (the monotonic clock). Any thread.
  std::int64_t quiet_ms() const;
  /// The socket (for ExitZero's last message: servo/exit_zero.h).
  int fd() const { return fd_; }
  /// Every send from now on goes through `fence` (null: none). The fence must outlive its use:
  /// set null before it is destroyed. Any thread.
  void set_fence(SendFence* fence) { fence_.store(fence); }
  /// Shuts the socket down (a blocked read returns).
  void shutdown();

 private:
  int fd_;
  int timeout_ms_;
  int message_timeout_ms_;
  std::chrono::steady_clock::time_point message_start_;
  const std::atomic<bool>* stop_;
  std::string why_;
  std::mutex send_mu_;
  std::atomic<SendFence*> fence_{nullptr};
  std::atomic<bool> alive_{true};
  std::atomic<std::int64_t> last_in_ns_;  ///< steady_clock (CLOCK_MONOTONIC) nanoseconds of the last byte received, or of the connection
};

}  // namespace isotouch::service
