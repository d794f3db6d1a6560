#include "isotouch/service/igtl_reply_rule.h"

namespace isotouch::service {

bool IgtlReplyRule::judge_now(std::int64_t t, std::int64_t away_ns) {
  const bool away = last_poll_ns_ != 0 && t - last_poll_ns_ > away_ns && !skipped_;
  last_poll_ns_ = t;
  skipped_ = away;  // never two in a row: a writer that is always late still judges every other poll
  return !away;
}

IgtlReply IgtlReplyRule::step(std::uint64_t pose_sequence, std::int64_t pose_received_ns,
                              const servo::StallLook& look, std::int64_t t) {
  if (look.stalled_now) {  // the servo stopped writing: the peer gets a zero now, not with the next pose
    zero_sent_ = true;
    return {true, {}, IgtlReply::Why::kStall};
  }
  if (t - pose_received_ns > stale_ns_) {  // the stream stopped (or never began): one zero
    const bool send = !zero_sent_;
    zero_sent_ = true;
    return {send, {}, send ? IgtlReply::Why::kStale : IgtlReply::Why::kNone};
  }
  // Wait for the servo to answer the newest pose (at most 2 ms): the force answers it (a write
  // made after the pose came but from the pose before is not its answer).
  if (pose_sequence == answered_ || (look.on && look.answers < pose_sequence && t - pose_received_ns < 2'000'000))
    return {};
  answered_ = pose_sequence;
  zero_sent_ = look.force_n.x == 0 && look.force_n.y == 0 && look.force_n.z == 0;
  // zero unless on
  return {true, look.force_n, look.on && look.answers >= pose_sequence ? IgtlReply::Why::kAnswer : IgtlReply::Why::kLate};
}

}  // namespace isotouch::service
