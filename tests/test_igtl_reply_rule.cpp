// IgtlReplyRule on a simulated clock: what `--haptic igtl:`'s writer sends its peer at each
// poll, timed exactly (the wall-clock tests in test_igtl_device.cpp check the same over a real
// socket with slack for the machine's scheduling). The servo's side is the real StallRule.
#include <gtest/gtest.h>

#include <cstdint>
#include <set>
#include <vector>

#include "isotouch/service/igtl_reply_rule.h"
#include "isotouch/service/stream_replies.h"
#include "isotouch/servo/stall_rule.h"

namespace isotouch::service {
namespace {

constexpr std::int64_t kMs = 1'000'000;

struct Sent {
  std::int64_t t;
  core::Vec3 f;
};

/// A stream (a pose every `period` from 1 ms: 500 Hz unless said), a 1 kHz servo writing `f` 0.4 ms after each
/// ms while t < servo_until, the writer polling every 0.2 ms until `end`; the stream stops
/// after stream_until. The stall time 2.5 ms (the servo's 2.5 periods); stale after 3 periods.
struct Sim {
  std::int64_t period = 2 * kMs, stream_until = 1000 * kMs, servo_until = 1000 * kMs, end = 100 * kMs;
  /// The machine froze every thread over [freeze_from, freeze_to): no pose taken, no write or
  /// poll; 0.2 ms after it the servo, whose deadline passed, writes (if it still runs) and the
  /// reader takes the newest of the poses the peer (another machine) sent meanwhile.
  std::int64_t freeze_from = -1, freeze_to = -1;
  /// The writer polls every `poll` (0.2 ms, as IgtlDevice's) and judges a gap over 5 nominal
  /// polls (1 ms) as its own freeze.
  std::int64_t poll = kMs / 5, away = kMs;
  core::Vec3 f{0.5, -0.25, 1.0};
  std::int64_t last_pose_ns = 0;
  std::vector<Sent> run() {
    servo::StallRule rule;
    rule.enable(true, 0.0025, 0.05, 0);
    rule.restart(0);
    IgtlReplyRule reply(3 * period);
    std::vector<Sent> sent;
    std::uint64_t seq = 0;
    std::int64_t received = 0;
    for (std::int64_t t = 0; t <= end; t += kMs / 5) {
      if (t >= freeze_from && t < freeze_to) continue;
      const bool resumed = t == freeze_to + kMs / 5;
      if ((t % period == kMs || resumed) && t <= stream_until) ++seq, received = t, last_pose_ns = t;
      if ((t % kMs == 2 * kMs / 5 || resumed) && t < servo_until) rule.write(f, seq, t);
      if (t % poll != 0) continue;
      if (!reply.judge_now(t, away)) continue;
      const IgtlReply r = reply.step(seq, received, rule.look(t), t);
      if (r.send) sent.push_back({t, r.force_n});
    }
    return sent;
  }
};

bool is_zero(const core::Vec3& f) { return f.x == 0 && f.y == 0 && f.z == 0; }

// Each pose is answered once with the servo's force, after the servo has answered it.
TEST(IgtlReplyRule, EachPoseGetsTheServosForceOnce) {
  Sim sim;
  sim.end = 40 * kMs;
  const std::vector<Sent> sent = sim.run();
  ASSERT_EQ(sent.size(), 20u);  // poses at 1, 3, ..., 39 ms
  for (std::size_t i = 0; i < sent.size(); ++i) {
    const std::int64_t pose = std::int64_t(2 * i + 1) * kMs;
    EXPECT_GE(sent[i].t, pose) << i;
    EXPECT_LE(sent[i].t, pose + kMs) << "pose " << i << " waited past the servo's next write";
    if (i > 0) {
      EXPECT_TRUE(sent[i].f.x == sim.f.x && sent[i].f.y == sim.f.y && sent[i].f.z == sim.f.z) << i;
    }
  }
}

// The stream stops: exactly one zero, at the first poll more than 3 stream periods (6 ms) after
// the last pose, nothing after it.
TEST(IgtlReplyRule, AStaleStreamGetsOneZeroAtThreePeriods) {
  Sim sim;
  sim.stream_until = 30 * kMs;
  const std::vector<Sent> sent = sim.run();
  ASSERT_FALSE(sent.empty());
  const Sent& last = sent.back();
  EXPECT_TRUE(is_zero(last.f)) << "the peer holds the last force: " << last.f.x;
  EXPECT_GT(last.t - sim.last_pose_ns, 6 * kMs);
  EXPECT_LE(last.t - sim.last_pose_ns, 6 * kMs + kMs / 5) << "the stale zero came after the first poll past 6 ms";
  for (std::size_t i = 0; i + 1 < sent.size(); ++i) EXPECT_FALSE(is_zero(sent[i].f) && sent[i].t > kMs) << i;
}

// The servo stops writing between two poses of a 100 Hz stream: the zero goes out at the poll
// that counts the stall (2.5 ms after the last write, plus at most a poll), not with the next
// pose.
TEST(IgtlReplyRule, AStalledServoGetsTheZeroAtOnce) {
  Sim sim;
  sim.period = 10 * kMs;
  sim.servo_until = 14 * kMs;  // last write at 13.4 ms; poses at 11 and 21 ms
  sim.end = 25 * kMs;
  const std::vector<Sent> sent = sim.run();
  const std::int64_t last_write = 13 * kMs + 2 * kMs / 5;
  const Sent* first_zero = nullptr;  // then the pose at 21 ms is answered: a zero too
  for (const Sent& s : sent)
    if (s.t > last_write && is_zero(s.f) && !first_zero) first_zero = &s;
  ASSERT_NE(first_zero, nullptr) << "no zero after the servo stopped";
  const Sent& zero = *first_zero;
  EXPECT_GT(zero.t - last_write, 5 * kMs / 2);
  EXPECT_LE(zero.t - last_write, 5 * kMs / 2 + kMs / 5) << "the zero waited";
  EXPECT_LT(zero.t, 21 * kMs) << "the zero waited for the next pose";
}

// The machine freezes every thread for 10 ms (a VM losing the CPU): the writer, back first,
// does not judge the servo stalled before it has had one poll to write; no zero, the force
// goes on.
TEST(IgtlReplyRule, AFrozenMachineIsNotAServoStall) {
  Sim sim;
  sim.freeze_from = 10 * kMs, sim.freeze_to = 20 * kMs;
  sim.end = 30 * kMs;
  const std::vector<Sent> sent = sim.run();
  ASSERT_GT(sent.size(), 5u);
  for (std::size_t i = 1; i < sent.size(); ++i) EXPECT_FALSE(is_zero(sent[i].f)) << "a zero at " << double(sent[i].t) * 1e-6 << " ms";
}

// The same freeze, and the servo does not come back: its zero at the second poll after it.
TEST(IgtlReplyRule, AServoStoppedThroughAFreezeGetsItsZeroOnePollLater) {
  Sim sim;
  sim.freeze_from = 10 * kMs, sim.freeze_to = 20 * kMs;
  sim.servo_until = 10 * kMs;
  sim.end = 30 * kMs;
  const std::vector<Sent> sent = sim.run();
  const Sent* zero = nullptr;
  for (const Sent& s : sent)
    if (s.t > kMs && is_zero(s.f) && !zero) zero = &s;
  ASSERT_NE(zero, nullptr) << "no zero for a servo that stopped";
  EXPECT_EQ(zero->t, 20 * kMs + kMs / 5) << "the zero came at " << double(zero->t) * 1e-6 << " ms";
}

// A writer that is always late (a poll every 3 ms, over its 1 ms "away") still judges every
// other poll: a servo that stops gets its zero within the stall time and two polls.
TEST(IgtlReplyRule, AnAlwaysLateWriterStillSendsTheStallsZero) {
  Sim sim;
  sim.poll = 3 * kMs;
  sim.servo_until = 10 * kMs;  // last write at 9.4 ms
  sim.end = 40 * kMs;
  const std::vector<Sent> sent = sim.run();
  const std::int64_t last_write = 9 * kMs + 2 * kMs / 5;
  const Sent* zero = nullptr;
  for (const Sent& s : sent)
    if (s.t > last_write && is_zero(s.f) && !zero) zero = &s;
  ASSERT_NE(zero, nullptr) << "no zero: the late writer judged nothing";
  EXPECT_LE(zero->t - last_write, 5 * kMs / 2 + 2 * sim.poll) << "the zero came at " << double(zero->t) * 1e-6 << " ms";
}

// A write made after a pose came but computed from the pose before is not its answer: the
// writer waits for the write that answers it.
TEST(IgtlReplyRule, AWriteFromThePoseBeforeIsNotTheAnswer) {
  servo::StallRule rule;
  rule.enable(true, 0.010, 0.05, 0);
  rule.restart(0);
  IgtlReplyRule reply(60 * kMs);
  rule.write({1, 0, 0}, 1, kMs / 2);
  (void)reply.step(1, 0, rule.look(kMs / 2), kMs / 2);       // pose 1 answered
  rule.write({2, 0, 0}, 1, 2 * kMs + kMs / 5);                 // after pose 2 came, from pose 1
  EXPECT_FALSE(reply.step(2, 2 * kMs, rule.look(2 * kMs + kMs / 5), 2 * kMs + kMs / 5).send);
  rule.write({3, 0, 0}, 2, 3 * kMs);                           // pose 2's answer
  const IgtlReply r = reply.step(2, 2 * kMs, rule.look(3 * kMs), 3 * kMs);
  EXPECT_TRUE(r.send);
  EXPECT_EQ(r.force_n.x, 3.0) << "pose 2 answered with a force from pose 1";
}

// A servo that has not answered the newest pose is waited for 2 ms at most; before any write
// (force off) the answer is an exact zero.
TEST(IgtlReplyRule, AnUnansweredPoseWaitsTwoMillisecondsAtMost) {
  servo::StallRule rule;
  rule.enable(true, 0.010, 0.05, 0);
  rule.restart(0);
  IgtlReplyRule reply(60 * kMs);
  EXPECT_TRUE(is_zero(reply.step(1, 0, rule.look(0), 0).force_n));  // nothing written yet: off, zero
  EXPECT_TRUE(reply.step(1, 0, rule.look(0), 0).send == false);     // answered once
  rule.write({1, 0, 0}, 1, kMs);
  EXPECT_FALSE(reply.step(2, 2 * kMs, rule.look(2 * kMs), 2 * kMs).send);  // the servo wrote before the pose
  EXPECT_FALSE(reply.step(2, 2 * kMs, rule.look(3 * kMs), 3 * kMs).send);
  const IgtlReply late = reply.step(2, 2 * kMs, rule.look(4 * kMs + 1), 4 * kMs + 1);
  EXPECT_TRUE(late.send) << "a pose the servo has not answered in 2 ms is answered with its newest force";
  EXPECT_EQ(late.force_n.x, 1.0);
}


// serve's reply thread (`serve --reply-force`, StreamReplyPoll) and `--haptic igtl:`'s writer
// (IgtlReplyRule, as IgtlDevice::write_loop polls it) decide alike, poll by poll, on one
// scripted stream and servo: a 500 Hz stream, a 1 kHz servo, a write made after a pose came
// but from the pose before, a 10 ms freeze of every thread, a servo that stalls for 10 ms and
// comes back, a stream that stops. Each side has its own StallRule written alike (a look
// counts a stall once). And what they agree on is what the script says is due: each pose
// answered once, the stall's zero within the stall time and a poll, one stale zero at the
// first poll past the stale time and nothing after it.
TEST(IgtlReplyRule, ServesReplyThreadAndTheIgtlWriterDecideAlike) {
  constexpr std::int64_t kPoll = kMs / 10, kStale = 6 * kMs, kStall = 5 * kMs / 2;
  servo::StallRule writer_stall, replies_stall;
  for (servo::StallRule* r : {&writer_stall, &replies_stall}) r->enable(true, 0.0025, 0.05, 0), r->restart(0);
  IgtlReplyRule writer(kStale);
  service::StreamReplyPoll replies(kStale);
  std::uint64_t seq = 0;
  std::int64_t received = 0, last_pose = 0, last_write_before_stall = 0;
  const std::int64_t freeze_from = 30 * kMs, freeze_to = 40 * kMs, stall_from = 50 * kMs, stall_to = 60 * kMs,
                     stream_until = 80 * kMs;
  std::vector<Sent> sent;
  std::vector<std::uint64_t> answered;  // the pose each answer went to
  long polls = 0;
  for (std::int64_t t = 0; t <= 100 * kMs; t += kPoll) {
    if (t >= freeze_from && t < freeze_to) continue;
    const bool resumed = t == freeze_to;
    if ((t % (2 * kMs) == kMs || resumed) && t <= stream_until) ++seq, received = t, last_pose = t;
    const core::Vec3 f{0.5 * double(seq % 3 + 1), -0.25, 1.0};
    auto write = [&](const core::Vec3& v, std::uint64_t answers) {
      writer_stall.write(v, answers, t), replies_stall.write(v, answers, t);
    };
    const bool servo_runs = t < stall_from || t >= stall_to;
    if (t % (2 * kMs) == kMs + kPoll && seq > 1 && servo_runs) write(f * 2.0, seq - 1);  // after the pose came, from the one before
    if ((t % kMs == 4 * kPoll || resumed) && servo_runs) {
      write(f, seq);
      if (t < stall_from) last_write_before_stall = t;
    }
    const bool judge_w = writer.judge_now(t, 5 * kPoll), judge_r = replies.judge_now(t);
    ASSERT_EQ(judge_w, judge_r) << "at " << double(t) * 1e-6 << " ms";
    if (!judge_w) continue;
    ++polls;
    const IgtlReply w = writer.step(seq, received, writer_stall.look(t), t);
    const IgtlReply r = replies.step({seq, received, 0}, {seq, received, 0}, replies_stall.look(t), t);
    ASSERT_EQ(w.send, r.send) << "at " << double(t) * 1e-6 << " ms";
    ASSERT_TRUE(w.why == r.why && w.force_n.x == r.force_n.x && w.force_n.y == r.force_n.y && w.force_n.z == r.force_n.z)
        << "at " << double(t) * 1e-6 << " ms: " << w.force_n.x << " against " << r.force_n.x;
    if (!r.send) continue;
    replies.sent(true);
    sent.push_back({t, r.force_n});
    if (r.why == IgtlReply::Why::kAnswer || r.why == IgtlReply::Why::kLate) answered.push_back(seq);
  }
  ASSERT_GT(polls, 800);
  // Each pose answered once.
  EXPECT_EQ(std::set<std::uint64_t>(answered.begin(), answered.end()).size(), answered.size()) << "a pose answered twice";
  EXPECT_EQ(answered.size(), std::size_t(seq)) << "poses not answered";
  // The stall's zero: the first zero after the servo's last write before it.
  const Sent* stall_zero = nullptr;
  for (const Sent& x : sent)
    if (x.t > last_write_before_stall && is_zero(x.f) && !stall_zero) stall_zero = &x;
  ASSERT_NE(stall_zero, nullptr) << "no zero for the stall";
  EXPECT_GT(stall_zero->t - last_write_before_stall, kStall);
  EXPECT_LE(stall_zero->t - last_write_before_stall, kStall + kPoll) << "the stall's zero waited";
  // The stale stream: its last send is one zero at the first poll past the stale time.
  ASSERT_FALSE(sent.empty());
  EXPECT_TRUE(is_zero(sent.back().f));
  EXPECT_EQ(sent.back().t, last_pose + kStale + kPoll) << "the stale zero at " << double(sent.back().t) * 1e-6 << " ms";
  EXPECT_FALSE(is_zero(sent[sent.size() - 2].f)) << "more than one zero for the stale stream";
}

// A pose the servo answered after a newer pose came is answered with its own force, and the
// stream's age is the newest pose's: the servo's late answer to an older pose (older than the
// stale time) is still an answer, not the stale stream's zero.
TEST(IgtlReplyRule, ServesReplyToAnOlderPoseJudgesStalenessByTheNewest) {
  constexpr std::int64_t kStale = 6 * kMs;
  servo::StallRule stall;
  stall.enable(true, 0.0025, 0.05, 0), stall.restart(0);
  service::StreamReplyPoll replies(kStale);
  const TransformDevice::PoseId older{7, 1 * kMs, 70}, newest{8, 8 * kMs, 80};
  const core::Vec3 f{0.5, -0.25, 1.0};
  const std::int64_t t = 8 * kMs + kMs / 5;  // the older pose is 7.2 ms old, past the stale time
  stall.write(f, older.sequence, t - kMs / 10);  // the servo's answer to pose 7, after pose 8 came
  const servo::StallLook l = stall.look(t);
  ASSERT_TRUE(replies.judge_now(t));
  const TransformDevice::PoseId p = service::StreamReplyPoll::pick(newest, older, l, 6);
  ASSERT_EQ(p.sequence, older.sequence) << "the servo's pose is not the one answered";
  const IgtlReply r = replies.step(p, newest, l, t);
  ASSERT_TRUE(r.send);
  EXPECT_EQ(int(r.why), int(IgtlReply::Why::kAnswer)) << "the older pose's age was taken for the stream's";
  EXPECT_EQ(r.force_n.x, f.x);
  // A pose the ring no longer keeps (sequence 0) leaves the newest to answer.
  EXPECT_EQ(service::StreamReplyPoll::pick(newest, {}, l, 6).sequence, newest.sequence);
}

}  // namespace
}  // namespace isotouch::service
