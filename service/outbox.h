// outbox.h - one client's sends that must not be lost (STATUS answers, edited IMAGEs), queued
// and sent by a thread of its own, so that no other thread (serve's command, main and display
// threads) ever waits for that peer. Bounded: a client whose queue would pass the bound is not
// reading, and is dropped (its connection shut down: its reader ends and its slot is freed);
// each message has one deadline for the whole of it (Connection::send), past which the client
// is dropped too. Part of isotouch::service.
#pragma once
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "isotouch/service/igtl_socket.h"

namespace isotouch::service {

class Outbox {
 public:
  using Bytes = std::shared_ptr<const std::vector<std::uint8_t>>;
  /// Sends to `conn` from its own thread. `max_queued_bytes`: the most bytes waiting behind
  /// the message being sent (one message is always taken when none waits, whatever its
  /// size). `on_drop(why)`: called once, from any thread, when the client is dropped.
  Outbox(std::shared_ptr<Connection> conn, std::size_t max_queued_bytes, std::function<void(const std::string&)> on_drop);
  /// close()
  ~Outbox();
  Outbox(const Outbox&) = delete;
  Outbox& operator=(const Outbox&) = delete;

  /// Queues `bytes` to be sent after those queued before; never waits for the peer. False
  /// when the client is gone or dropped, or is dropped now (the bound passed).
  bool push(Bytes bytes);
  bool push(std::vector<std::uint8_t> bytes) {
    return push(std::make_shared<const std::vector<std::uint8_t>>(std::move(bytes)));
  }
  /// Waits up to `timeout_ms` until everything queued was sent (or the client dropped).
  /// True when the queue is empty.
  bool flush(int timeout_ms);
  /// Sends nothing more (what is queued is discarded) and joins the thread. Idempotent. The
  /// connection is not shut down: a send under way ends at its deadline, so shut it first.
  void close();
  const std::shared_ptr<Connection>& connection() const { return conn_; }
  /// Messages sent whole so far.
  long sent() const;

 private:
  void run();
  void drop(const std::string& why);

  std::shared_ptr<Connection> conn_;
  std::size_t max_bytes_;
  std::function<void(const std::string&)> on_drop_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Bytes> queue_;
  std::size_t queued_bytes_ = 0;
  bool sending_ = false;  // the thread holds a message taken off the queue
  bool closed_ = false, dropped_ = false;
  std::atomic<bool> drop_once_{false};  // drop() acts once
  long sent_ = 0;
  std::thread thread_;
};

}  // namespace isotouch::service
