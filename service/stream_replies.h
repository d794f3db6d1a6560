// stream_replies.h - `isotouch serve --reply-force`: each pose of the TRANSFORM stream is
// answered, on a thread of its own, with the force the servo rendered for it, sent to the
// client whose pose it was, as PLUS's device loop expects (lock-step: the pose's header stamp
// echoed). The safety rules of every force path (servo/stall_rule.h) hold here too:
//   - the servo stops writing for its stall time: a zero goes out at once, whole, and nothing
//     but zeros until the servo writes again (it ramps in after);
//   - the stream goes stale (no pose for `stale_s`): one zero, whole (the client holds the
//     last Force it got);
//   - a client that stops being the stream's is left a zero; the loop's last act is a zero;
//   - however the process ends (a crash, a second stop signal, a stuck servo's _Exit) the
//     client's last message is a zero (ExitZeroFence, servo/exit_zero.h).
// Part of isotouch::igtl_device.
#pragma once
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/service/igtl_reply_rule.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/transform_device.h"

namespace isotouch::service {

/// The reply thread's decision at one poll, without its clock and socket (the tests drive it
/// on a simulated clock): IgtlReplyRule's, the one rule of every igtl force path (`--haptic
/// igtl:`'s writer too): each pose answered once, one zero when the stream goes stale, a
/// stall's zero at once; a stall's or a stale stream's zero goes whole (IgtlReply::whole).
class StreamReplyPoll {
 public:
  static constexpr std::int64_t kPollNs = 100'000;    ///< the reply thread's poll [ns]
  static constexpr std::int64_t kAwayNs = 5 * kPollNs;  ///< a gap this long: the thread itself was away
  /// Another send to the client under way (serve's display TRANSFORMs to the same client: a
  /// few microseconds) is waited for this long before a reply is dropped [ns].
  static constexpr std::int64_t kBusyWaitNs = 300'000;
  explicit StreamReplyPoll(std::int64_t stale_ns) : rule_(stale_ns) {}
  /// Before the stall rule's look at t [ns]: false when this poll judges nothing (the reply
  /// thread was itself away: IgtlReplyRule::judge_now).
  bool judge_now(std::int64_t t) { return rule_.judge_now(t, kAwayNs); }
  /// The pose this poll answers: `newest`, or the pose the servo answered (`servo_answered`,
  /// TransformDevice::recent_pose(l.answers); sequence 0 when no longer kept) when it is newer
  /// than the last one answered (`last_answered`) and is not the newest: a newer pose overtook
  /// it before this poll, or the servo read one that came between the two reads. So a force
  /// never goes out with another pose's stamp.
  static TransformDevice::PoseId pick(const TransformDevice::PoseId& newest, const TransformDevice::PoseId& servo_answered,
                                      const servo::StallLook& l, std::uint64_t last_answered) {
    const bool other = l.on && l.answers > last_answered && l.answers != newest.sequence;
    return other && servo_answered.sequence == l.answers ? servo_answered : newest;
  }
  /// p: the pose picked; newest: the newest pose read (the stream is stale by its age, not by
  /// an older pose's the servo answered late).
  IgtlReply step(const TransformDevice::PoseId& p, const TransformDevice::PoseId& newest, const servo::StallLook& l,
                 std::int64_t t) {
    return rule_.step(p.sequence, std::max(p.received_ns, newest.received_ns), l, t);
  }
  /// What became of what step() said to send: a dropped send leaves a stale zero owed.
  void sent(bool delivered) {
    if (!delivered) rule_.undelivered();
  }
  /// The client was left a zero outside step() (it stopped being the replies' target).
  void zero_given() { rule_.zero_given(); }

 private:
  IgtlReplyRule rule_;
};

struct StreamReplyOptions {
  bool sched_fifo = false;  ///< SCHED_FIFO 70 (below the servo's 80) for the reply thread where allowed
  double stale_s = 0.1;     ///< no pose for this long [s]: the client is sent one zero
};

class StreamReplies {
 public:
  /// The connection the replies go to now (the client whose TRANSFORM moved the HIP last);
  /// null: none. Called once a reply, never on the servo thread.
  using Target = std::function<std::shared_ptr<Connection>()>;
  /// `log` gets one line if the thread's priority could not be raised.
  StreamReplies(TransformDevice& device, StreamReplyOptions o, Target target,
                std::function<void(const std::string&)> log = {});
  /// The reply loop, on the calling thread, until `stop`; its last act: a zero to the client.
  /// The thread takes no stop signal from then on (block_stop_signals).
  void run(const std::atomic<bool>& stop);
  /// The target changed at once (serve refused its client's stream): the reply thread asks
  /// target() at its next poll, and a connection that stopped being it is left a zero, whole,
  /// there and then (the path every Force takes, not the stale timeout's). Returns true once
  /// that was done; false after `timeout_s`, or at once when run() is not running. Not on the
  /// servo thread (it sleeps).
  bool retarget(double timeout_s);
  /// Zeros sent by retarget() to a connection that stopped being the target.
  long retarget_zeros() const { return retarget_zeros_.load(); }
  long replies() const { return replies_.load(); }  ///< Force replies sent
  /// Of those: a pose the servo did not render within 2 ms (no session running: zero).
  long stall_replies() const { return stall_replies_.load(); }
  /// Poses the replies passed over: between two poses answered, those not answered (the
  /// servo never read them, TransformDevice::overtaken(), or the servo's answer to them was
  /// replaced by its next before this thread's poll saw it).
  long passed_over() const { return passed_over_.load(); }
  /// Replies dropped, the connection kept: another send to the client was under way, or its
  /// buffers were full (Connection::try_send).
  long dropped() const { return dropped_.load(); }
  /// Where a rendered reply's time went [us], for each reply the servo rendered: from the
  /// pose's arrival to the servo's write, and from that write to the send. After run().
  struct Split {
    double to_servo_p50_us = 0, to_servo_p99_us = 0, to_send_p50_us = 0, to_send_p99_us = 0;
  };
  Split split() const;

 private:
  TransformDevice& device_;
  StreamReplyOptions o_;
  Target target_;
  std::function<void(const std::string&)> log_;
  std::atomic<long> replies_{0}, stall_replies_{0}, retarget_zeros_{0}, passed_over_{0}, dropped_{0};
  std::atomic<std::uint64_t> retarget_asked_{0}, retarget_done_{0};  // retarget(): asked, handled up to
  std::atomic<bool> running_{false};
  // Histograms of the two parts of each rendered reply, 10 us bins up to 10 ms (the last:
  // beyond); the reply thread's own until run() returns.
  static constexpr int kBins = 1000;
  std::vector<long> to_servo_, to_send_;
};

}  // namespace isotouch::service
