// stream_host.h - serve's TRANSFORM stream in miniature, for the tests and `isotouch bench
// device`: a TransformDevice fed by whoever connects (each client's "StylusToTracker"
// TRANSFORMs pushed to it, and that client made the replies' target, as serve's handle()
// does) and serve's own StreamReplies answering on a thread of its own. No Vulkan, no session: the caller's servo drives
// device(). Part of isotouch::plus_peer.
#pragma once
#include <atomic>
#include <list>
#include <memory>
#include <mutex>
#include <thread>

#include "isotouch/service/igtl_message.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/stream_replies.h"
#include "isotouch/service/transform_device.h"

namespace isotouch::service {

class StreamHost {
 public:
  /// Listens on 127.0.0.1 (any free port) and starts the reply thread.
  /// @throws std::runtime_error if it cannot listen.
  explicit StreamHost(StreamReplyOptions o);
  ~StreamHost();  ///< stop()
  StreamHost(const StreamHost&) = delete;
  StreamHost& operator=(const StreamHost&) = delete;
  int port() const { return listener_.port(); }
  TransformDevice& device() { return device_; }
  StreamReplies& replies() { return replies_; }
  /// Stops the replies (their last act: a zero to the stream's client), then the clients.
  void stop();

 private:
  void accept_loop();
  void read_loop(const std::shared_ptr<Connection>& conn);

  Listener listener_;
  TransformDevice device_;
  std::mutex mu_;
  std::shared_ptr<Connection> target_;
  std::list<std::shared_ptr<Connection>> conns_;
  std::list<std::thread> clients_;
  std::atomic<bool> stop_{false}, stop_replies_{false};
  StreamReplies replies_;
  std::thread accepting_, replying_;
};

}  // namespace isotouch::service
