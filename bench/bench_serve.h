// bench_serve.h - `isotouch bench serve`: the round trip of `isotouch serve` on loopback, from
// a tracker's TRANSFORM in to the force TRANSFORM that answers it (--reply-force), with and
// without Slicer-like traffic in the same run (a large IMAGE every few seconds, each one
// becoming the session's volume), and the servo's missed deadlines in both.
#pragma once
#include <array>
#include <iosfwd>
#include <string>
#include <vector>

namespace isotouch::bench {

struct BenchServeOptions {
  std::string scene;           ///< the scene served ("" = scenes/head.json)
  double seconds = 8;          ///< per phase [s]
  double rate_hz = 1000;       ///< the tracker's TRANSFORMs per second
  int image_size = 256;        ///< the IMAGE's voxels per axis (float32)
  double image_every_s = 3;    ///< one IMAGE this often [s]
  bool sched_fifo = true;      ///< SCHED_FIFO for the servo thread (refused: a note)
  std::string device;          ///< Vulkan device
};

/// One phase's figures.
struct BenchServePhase {
  std::string name;
  long poses = 0;              ///< TRANSFORMs sent
  long answered = 0;           ///< force TRANSFORMs received that answer one of them
  long stall_answers = 0;      ///< of those, the server's: no servo rendered the pose within 2 ms (a session swap)
  double p50_us = 0, p99_us = 0, max_us = 0;  ///< round trip, pose sent to its force received [us]
  long images = 0;             ///< IMAGEs taken as the session's volume
  long ticks = 0, missed = 0;  ///< servo ticks and missed deadlines
  /// Inside the server, for the replies the servo rendered [us]: the pose's arrival to the
  /// servo's write (the wait for a tick and the tick), and that write to the send (p50, p99).
  double to_servo_p50_us = 0, to_servo_p99_us = 0, to_send_p50_us = 0, to_send_p99_us = 0;
  double stream_late_us = 0;  ///< the stream's arrival lateness (99.5th percentile) at the end [us]
  long input_waits = 0;       ///< servo ticks that waited for a pose later than the lead
  long input_wait_timeouts = 0;  ///< of those, the waits that ended without the pose
  long unanswered = 0;                  ///< poses sent that no force answered
  long unanswered_first_second = 0;     ///< of those, in the phase's first second
  long unanswered_sent_late = 0;        ///< of those, sent >= 250 us behind the tracker's own schedule
  long unanswered_after_unanswered = 0; ///< of those, right after another unanswered pose
  double tracker_late_p99_us = 0, tracker_late_p999_us = 0;  ///< the tracker's send lateness [us]
  long passed_over = 0;  ///< poses the server's replies passed over (ServeStats::passed_over)
  long overtaken = 0;    ///< of those, poses the servo never read (ServeStats::overtaken)
  long dropped = 0;      ///< replies the server dropped (ServeStats::replies_dropped)
  std::array<long, 5> overtaken_gaps{};  ///< the poses never read by how soon the next came (ServeStats)
};

/// "p99 round trip with traffic = X us: target <= 1000 us met|NOT met", "poses answered
/// alone|with traffic A of P = X %: target >= 99 % met|NOT met" (one each) and "servo misses
/// with traffic M <= R + 3 sqrt(R) = L (R without): met|NOT met", from the figures.
std::vector<std::string> bench_serve_verdicts(const BenchServePhase& alone, const BenchServePhase& traffic);

/// Runs both phases and prints a table, the verdicts and the machine. @return 0; 1 if
/// nothing could be measured.
int run_bench_serve(const BenchServeOptions& options, std::ostream& log);

}  // namespace isotouch::bench
