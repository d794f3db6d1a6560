#include "isotouch/service/plus_peer.h"

#include <algorithm>
#include <chrono>

#include "isotouch/servo/cpu_placement.h"

namespace isotouch::service {

std::int64_t PlusPeer::now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

PlusPeer::PlusPeer(PlusPeerOptions o) : o_(std::move(o)) {
  if (o_.connect_host.empty()) listener_ = std::make_unique<Listener>("127.0.0.1", 0);
  forces_.reserve(1 << 16), poses_.reserve(1 << 16);
  thread_ = std::thread([this] { run(); });
}

PlusPeer::~PlusPeer() { finish(); }

int PlusPeer::port() const { return listener_ ? listener_->port() : o_.connect_port; }

void PlusPeer::finish() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

std::vector<PeerForce> PlusPeer::forces() const {
  std::lock_guard<std::mutex> lock(mu_);
  return forces_;
}

std::vector<std::int64_t> PlusPeer::poses_ns() const {
  std::lock_guard<std::mutex> lock(mu_);
  return poses_;
}

void PlusPeer::run() {
  // A device loop's priority where allowed (PLUS's is): what it times is the link's.
  if (o_.fifo_priority > 0) servo::make_thread_realtime("plus peer", true, o_.fifo_priority, false, -1);
  int fd = -1;
  if (listener_) {
    while (fd < 0 && !stop_) fd = listener_->accept(50);
  } else {
    try {
      fd = connect_tcp(o_.connect_host, o_.connect_port, 2000);
    } catch (const std::exception&) {
      fd = -1;  // connected() stays false: the caller sees nothing arrive
    }
  }
  if (fd < 0) return;
  Connection conn(fd, 2000, 2000, &stop_);
  connected_ = true;
  std::thread reader([&] { read_forces(conn); });
  stream(conn);
  // Taken before the shutdown: the client may see the close, and read its own clock, before
  // this thread runs again after the call.
  closed_ns_ = now_ns();
  conn.shutdown();
  reader.join();
}

void PlusPeer::read_forces(Connection& conn) {
  if (o_.fifo_priority > 0) servo::make_thread_realtime("plus peer reader", true, o_.fifo_priority, false, -1);
  for (;;) {
    const Incoming in = read_message(conn, MessageLimits{});
    if (in.kind == Incoming::Kind::kClosed || in.kind == Incoming::Kind::kBroken) break;
    if (in.kind != Incoming::Kind::kTransform || in.device != "Force") continue;
    const PeerForce f{now_ns(), {in.matrix[0][3], in.matrix[1][3], in.matrix[2][3]}, in.stamp};
    std::lock_guard<std::mutex> lock(mu_);
    forces_.push_back(f);
  }
  client_gone_ = true;
}

void PlusPeer::stream(Connection& conn) {
  using Clock = std::chrono::steady_clock;
  const double pose[3] = {o_.pose_mm.x, o_.pose_mm.y, o_.pose_mm.z};
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / o_.rate_hz));
  const Clock::time_point t0 = Clock::now();
  started_ns_ = now_ns();
  const auto since_s = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  for (Clock::time_point next = t0; !stop_;) {
    std::this_thread::sleep_until(next);
    if (o_.stream_s > 0 && since_s() >= o_.stream_s) break;  // stopped: one period after the last pose
    if (o_.close_s > 0 && since_s() >= o_.close_s) break;
    if (!pause_.load()) {
      const std::vector<std::uint8_t> msg = pack_translation(o_.stream, pose);
      {
        std::lock_guard<std::mutex> lock(mu_);
        poses_.push_back(now_ns());
      }
      conn.send(msg);
    }
    next = std::max(next + period, Clock::now());
  }
  if (o_.stream_s > 0 && since_s() >= o_.stream_s) stopped_ns_ = now_ns();
  while (!stop_ && !(o_.close_s > 0 && since_s() >= o_.close_s)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

}  // namespace isotouch::service
