#include "isotouch/service/stream_host.h"

namespace isotouch::service {

StreamHost::StreamHost(StreamReplyOptions o)
    : listener_("127.0.0.1", 0), replies_(device_, o, [this] {
        std::lock_guard<std::mutex> lock(mu_);
        return target_;
      }) {
  accepting_ = std::thread([this] { accept_loop(); });
  replying_ = std::thread([this] { replies_.run(stop_replies_); });
}

StreamHost::~StreamHost() { stop(); }

void StreamHost::stop() {
  stop_replies_ = true;
  if (replying_.joinable()) replying_.join();
  stop_ = true;
  if (accepting_.joinable()) accepting_.join();  // conns_ and clients_ are this thread's now
  for (auto& c : conns_) c->shutdown();
  for (std::thread& t : clients_)
    if (t.joinable()) t.join();
}

void StreamHost::accept_loop() {
  while (!stop_) {
    const int fd = listener_.accept(20);
    if (fd < 0) continue;
    auto conn = std::make_shared<Connection>(fd, 2000, 2000, &stop_);
    conns_.push_back(conn);
    clients_.emplace_back([this, conn] { read_loop(conn); });
  }
}

/// As serve's client threads: each pose of the stream moves the device, and its sender
/// becomes the replies' target.
void StreamHost::read_loop(const std::shared_ptr<Connection>& conn) {
  for (;;) {
    const Incoming in = read_message(*conn, MessageLimits{});
    if (in.kind == Incoming::Kind::kClosed || in.kind == Incoming::Kind::kBroken) return;
    if (in.kind != Incoming::Kind::kTransform || in.device != "StylusToTracker") continue;
    {
      std::lock_guard<std::mutex> lock(mu_);
      target_ = conn;
    }
    const double t[3] = {in.matrix[0][3], in.matrix[1][3], in.matrix[2][3]};
    device_.push_mm(t, in.stamp);
  }
}

}  // namespace isotouch::service
