// tool_bench.h - the spherical tool's tick at servo rates (`bench table1`'s tool lines): the
// time of every single tick of a stroke, median and p99, for the point and for spheres of
// a few voxels' radius, measured side by side in the same run, and the verdict computed
// from them.
#pragma once
#include <string>
#include <vector>

#include "isotouch/eval/sweep.h"
#include "isotouch/servo/hri.h"

namespace isotouch::bench {

/// Per-tick figures of one renderer over the replays of a stroke [us].
struct TickSpread {
  double radius_voxels = 0;  ///< 0: the point
  double radius_m = 0;       ///< the tool's radius [m, world]; 0: the point
  double median_us = 0, p99_us = 0, max_us = 0;
  long ticks = 0;            ///< ticks timed (replays x stroke length)
};

/// One scene's tool lines: the point's ticks and each tool radius's, in the same rounds.
struct ToolTickRow {
  std::string scene;
  TickSpread point;
  std::vector<TickSpread> tools;
  double clock_ns = 0;  ///< the timer's own cost per reading pair, subtracted from every tick [ns]
};

/// The targets of the tool lines: the tool's p99 at most this [us] (4 kHz with margin), its
/// median at most this many times the point's.
inline constexpr double kToolP99LimitUs = 50.0;
inline constexpr double kToolMedianRatioLimit = 20.0;

/// Replays `s`'s stroke `reps` times (after `warmup` untimed) through HRI with `point`'s
/// parameters (the point) and with tools of `radii_voxels` x the smallest spacing, round by
/// round (each round starts one renderer later), timing every tick; median, p99 and max per
/// renderer, less the clock's own cost.
ToolTickRow measure_tool_ticks(const eval::SweepScene& s, const servo::HriParams& point,
                               const std::vector<double>& radii_voxels, int warmup, int reps);

/// "  SCENE: point median M us, p99 P us; tool r = R voxels (X mm): median M us (Q x the
/// point), p99 P us, max X us" (one line per tool).
std::string tool_tick_lines(const ToolTickRow& row);

/// Computed from `rows`: "tool ticks: p99 <= 50 us on k of N, median <= 20 x the point's on
/// j of N (worst p99: SCENE r = R voxels P us; worst ratio: ...): PASS" (FAIL when any misses;
/// no rows, or a non-finite or non-positive time: FAIL).
std::string tool_tick_verdict(const std::vector<ToolTickRow>& rows);

}  // namespace isotouch::bench
