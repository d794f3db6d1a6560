#pragma once
// isotouch::service::IgtlReplyRule - what `--haptic igtl:`'s writer sends its peer at each
// poll, as a function of the stream, the servo's stall rule and the time (no clock, no I/O):
// the writer thread (IgtlDevice::write_loop) polls it on the steady clock, the tests on a
// simulated one.
#include <cstdint>

#include "isotouch/core/vec3.h"
#include "isotouch/servo/stall_rule.h"

namespace isotouch::service {

/// One poll's answer: send `force_n` [N, the stream's frame] when `send`, for `why`.
struct IgtlReply {
  enum class Why {
    kNone,    ///< nothing to send
    kStall,   ///< the servo just stalled: a zero
    kStale,   ///< the stream went stale: its one zero
    kAnswer,  ///< the servo's answer to the newest pose (zero while off)
    kLate,    ///< the newest pose, not answered by the servo (off, or not within 2 ms): its newest force (zero while off)
  };
  bool send = false;
  core::Vec3 force_n;
  Why why = Why::kNone;
  /// A stall's or a stale stream's zero: never to be dropped (the peer keeps its last force).
  bool whole() const { return why == Why::kStall || why == Why::kStale; }
};

/// The writer's rule. At a poll at time t [ns] where the writer was not away (judge_now), in
/// order:
///   - the servo just stalled (StallLook::stalled_now): a zero at once, not with the next pose;
///   - the stream is stale (its newest pose older than stale_ns): one zero, then nothing;
///   - a pose not answered yet: the servo's newest force (zero while off), once the servo's
///     force answers it (StallLook::answers) or the pose is 2 ms old.
class IgtlReplyRule {
 public:
  /// stale_ns: no pose for this long [ns] and the peer is sent one zero (3 stream periods).
  explicit IgtlReplyRule(std::int64_t stale_ns) : stale_ns_(stale_ns) {}
  /// pose_sequence / pose_received_ns: the newest pose (0, 0 before any);
  /// look: the stall rule's look at t; t: the poll's time [ns].
  IgtlReply step(std::uint64_t pose_sequence, std::int64_t pose_received_ns, const servo::StallLook& look,
                 std::int64_t t);
  /// Before the stall rule's look at a poll at t [ns]: false when the writer itself was away
  /// (its previous poll more than away_ns ago, e.g. 5 polls: the machine froze this thread,
  /// and the servo's with it as likely as not) and the previous poll was judged: this poll
  /// judges nothing, and the next, one poll later, judges the servo that has had the CPU
  /// back. Never two polls in a row, so a servo that really stopped gets its zero at most one
  /// poll later than without this rule, also from a writer that is always late. It makes a
  /// frozen machine's false stall less likely, not impossible (a servo that gets the CPU back
  /// more than a poll after the writer is still judged stalled).
  bool judge_now(std::int64_t t, std::int64_t away_ns);
  /// The peer was given a zero outside step() (serve's reply target changed): no stale zero owed.
  void zero_given() { zero_sent_ = true; }
  /// The last force step() said to send did not reach the peer (a dropped send): it may hold
  /// an older force, so a stale stream is still owed its zero.
  void undelivered() { zero_sent_ = false; }

 private:
  std::int64_t stale_ns_;
  std::int64_t last_poll_ns_ = 0;  // 0: no poll yet
  bool skipped_ = false;           // the previous poll judged nothing
  std::uint64_t answered_ = 0;
  bool zero_sent_ = true;  // nothing sent yet: the peer holds no force
};

}  // namespace isotouch::service
