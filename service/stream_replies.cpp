#include "isotouch/service/stream_replies.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

#include "isotouch/service/igtl_device.h"
#include "isotouch/servo/cpu_placement.h"

namespace isotouch::service {

StreamReplies::StreamReplies(TransformDevice& device, StreamReplyOptions o, Target target,
                             std::function<void(const std::string&)> log)
    : device_(device), o_(o), target_(std::move(target)), log_(std::move(log)) {}

/// Polls every 0.1 ms and sends what IgtlReplyRule (StreamReplyPoll) says: a new pose on the
/// stream, once the servo's force answers it (or 2 ms later), is answered with that force;
/// while the force is off (no session runs, the servo stalled) at once with a zero.
namespace {
/// The 10 us bin of a delay [ns], the last of `bins` for all beyond.
std::size_t bin(std::int64_t ns, int bins) { return std::size_t(std::clamp<std::int64_t>(ns / 10'000, 0, bins - 1)); }

/// The q-quantile of a 10 us histogram [us] (the bin's middle); 0 when empty.
double quantile_us(const std::vector<long>& h, double q) {
  long n = 0;
  for (long c : h) n += c;
  if (n == 0) return 0;
  const auto want = long(std::ceil(q * double(n)));
  long seen = 0;
  for (std::size_t i = 0; i < h.size(); ++i)
    if ((seen += h[i]) >= want) return double(i) * 10 + 5;
  return double(h.size()) * 10;
}
}  // namespace

StreamReplies::Split StreamReplies::split() const {
  return {quantile_us(to_servo_, 0.5), quantile_us(to_servo_, 0.99), quantile_us(to_send_, 0.5),
          quantile_us(to_send_, 0.99)};
}

bool StreamReplies::retarget(double timeout_s) {
  const std::uint64_t ask = retarget_asked_.fetch_add(1) + 1;
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (retarget_done_.load() < ask) {
    if (!running_.load() || std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  return true;
}

void StreamReplies::run(const std::atomic<bool>& stop) {
  to_servo_.assign(kBins, 0);  // before the loop: no allocation in it
  to_send_.assign(kBins, 0);
  if (o_.sched_fifo)  // below the servo (80): the answer waits for nothing but the servo's tick
    if (const std::string note = servo::make_thread_realtime("serve reply thread", true, 70, false, -1).note;
        !note.empty() && log_)
      log_("reply    " + note);
  StreamReplyPoll poll(std::int64_t(o_.stale_s * 1e9));  // IgtlReplyRule: the one rule of the igtl force paths
  device_.restart_force(TransformDevice::now_ns());
  block_stop_signals();  // a stop signal's handler sends the last zero: never inside a send of this thread
  servo::ensure_signal_stack();  // a stack overflow here still sends the client its zero
  // The stream client's zero however serve ends: registered for the connection the replies go
  // to, fencing every send on it, kept alive (its socket open) while registered.
  std::shared_ptr<Connection> fenced;
  std::unique_ptr<ExitZeroFence> exit_zero;
  const double zero3[3] = {0, 0, 0};
  const std::vector<std::uint8_t> zero_msg = pack_translation("Force", zero3);
  const auto unfence = [&] {
    if (!fenced) return;
    fenced->send(zero_msg);  // blocking: the zero is not dropped
    fenced->set_fence(nullptr);
    exit_zero.reset();
    fenced.reset();
  };
  bool waiting = false;  // a pose the servo has not answered yet: looked for every 20 us, else 100 us
  std::uint64_t answered = 0;  // the last pose the rule said to answer
  running_ = true;
  while (!stop) {
    std::this_thread::sleep_for(std::chrono::nanoseconds(waiting ? StreamReplyPoll::kPollNs / 5 : StreamReplyPoll::kPollNs));
    if (const std::uint64_t ask = retarget_asked_.load(); ask != retarget_done_.load()) {
      if (target_() != fenced) {  // the client that stopped being it: a zero now
        if (fenced) retarget_zeros_.fetch_add(1);
        unfence();
        poll.zero_given();
      }
      retarget_done_ = ask;
    }
    const TransformDevice::PoseId newest = device_.newest_pose();
    const std::int64_t now = TransformDevice::now_ns();  // the clock before the cell
    if (!poll.judge_now(now)) continue;  // this thread was away: the servo gets a poll to write first
    const servo::StallLook l = device_.look_force(now);
    const TransformDevice::PoseId p = StreamReplyPoll::pick(newest, device_.recent_pose(l.answers), l, answered);
    const IgtlReply r = poll.step(p, newest, l, now);
    waiting = !r.send && l.on && p.sequence > l.answers && now - p.received_ns < 2'000'000;
    if (!r.send) continue;
    if (r.why == IgtlReply::Why::kAnswer || r.why == IgtlReply::Why::kLate) {
      if (answered != 0 && p.sequence > answered + 1) passed_over_.fetch_add(long(p.sequence - answered - 1));
      answered = std::max(answered, p.sequence);
    }
    // In the tracker's frame (the registration's R^T): the client applies it there.
    const core::Vec3 f = device_.to_tracker_n(device_.echo().to_ras_n(r.force_n));
    const double t[3] = {f.x, f.y, f.z};
    std::shared_ptr<Connection> to = target_();
    if (to != fenced) {
      unfence();  // a client that stops being the stream's is left a zero
      if (to) {
        exit_zero = std::make_unique<ExitZeroFence>(to->fd(), zero_msg);
        to->set_fence(exit_zero.get());
        fenced = to;
      }
    }
    if (!to) continue;
    // A zero for a stall or a stale stream is never dropped (the client would keep the last
    // force): sent whole, waiting for the client if need be; the rest never wait (a client
    // that does not read).
    const bool rendered = r.why == IgtlReply::Why::kAnswer;
    const std::vector<std::uint8_t> msg = pack_translation("Force", t, p.stamp);
    const Sent sent = r.whole() ? (to->send(msg) ? Sent::kSent : Sent::kDead) : to->try_send(msg, StreamReplyPoll::kBusyWaitNs);
    const bool delivered = sent == Sent::kSent;
    if (sent == Sent::kBusy || sent == Sent::kFull) dropped_.fetch_add(1);
    poll.sent(delivered);
    if (delivered) {
      replies_.fetch_add(1);
      stall_replies_.fetch_add(r.why == IgtlReply::Why::kLate);
      if (rendered && p.received_ns > 0) {
        const std::int64_t sent = TransformDevice::now_ns();
        ++to_servo_[bin(l.last_write_ns - p.received_ns, kBins)];
        ++to_send_[bin(sent - l.last_write_ns, kBins)];
      }
    }
  }
  running_ = false;
  unfence();  // the last act: the stream client (PLUS holds the last Force it got) is left a zero
}

}  // namespace isotouch::service
