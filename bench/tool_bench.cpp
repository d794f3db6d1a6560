#include "isotouch/bench/tool_bench.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <memory>
#include <sstream>

#include "isotouch/eval/stats.h"

namespace isotouch::bench {

namespace {

/// The median cost of one pair of steady_clock readings, as eval::playback takes around
/// each tick [ns].
double clock_pair_ns() {
  using clock = std::chrono::steady_clock;
  std::vector<double> d(20001);
  for (double& x : d) {
    const auto t0 = clock::now();
    const auto t1 = clock::now();
    x = std::chrono::duration<double, std::nano>(t1 - t0).count();
  }
  return eval::median(std::move(d));
}

TickSpread spread(std::vector<double> us, double radius_voxels, double radius_m) {
  TickSpread t;
  t.radius_voxels = radius_voxels;
  t.radius_m = radius_m;
  t.ticks = long(us.size());
  if (us.empty()) return t;
  t.max_us = *std::max_element(us.begin(), us.end());
  t.p99_us = eval::percentile(us, 0.99);
  t.median_us = eval::median(std::move(us));
  return t;
}

std::string fmt(double v, int p) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(p) << v;
  return s.str();
}

}  // namespace

ToolTickRow measure_tool_ticks(const eval::SweepScene& s, const servo::HriParams& point,
                               const std::vector<double>& radii_voxels, int warmup, int reps) {
  const double voxel = s.voxel_m;
  std::vector<std::unique_ptr<servo::HriRenderer>> rs;
  rs.push_back(std::make_unique<servo::HriRenderer>(point));
  for (double rv : radii_voxels) {
    servo::HriParams p = point;
    p.tool_radius_m = rv * voxel;
    rs.push_back(std::make_unique<servo::HriRenderer>(p));
  }
  const int k = int(rs.size());
  ToolTickRow row;
  row.scene = s.name;
  row.clock_ns = clock_pair_ns();
  std::vector<std::vector<double>> us(rs.size());
  for (auto& r : rs)
    for (int w = 0; w < warmup; ++w) (void)eval::playback(*r, s);
  for (int rep = 0; rep < reps; ++rep)
    for (int j = 0; j < k; ++j) {
      const int a = (rep + j) % k;
      const eval::Playback p = eval::playback(*rs[std::size_t(a)], s);
      for (std::int64_t ns : p.tick_ns) us[std::size_t(a)].push_back(std::max(0.0, double(ns) - row.clock_ns) * 1e-3);
    }
  row.point = spread(std::move(us[0]), 0, 0);
  for (std::size_t i = 0; i < radii_voxels.size(); ++i)
    row.tools.push_back(spread(std::move(us[i + 1]), radii_voxels[i], radii_voxels[i] * voxel));
  return row;
}

std::string tool_tick_lines(const ToolTickRow& row) {
  std::ostringstream s;
  s << "  " << row.scene << ": point median " << fmt(row.point.median_us, 3) << " us, p99 " << fmt(row.point.p99_us, 3)
    << " us, max " << fmt(row.point.max_us, 1) << " us (" << row.point.ticks << " ticks; clock " << fmt(row.clock_ns, 0)
    << " ns per tick subtracted)\n";
  for (const TickSpread& t : row.tools)
    s << "  " << row.scene << ": tool r = " << fmt(t.radius_voxels, 0) << " voxels (" << fmt(t.radius_m * 1e3, 2)
      << " mm): median " << fmt(t.median_us, 3) << " us (" << fmt(t.median_us / row.point.median_us, 1)
      << " x the point), p99 " << fmt(t.p99_us, 2) << " us, max " << fmt(t.max_us, 1) << " us\n";
  return s.str();
}

std::string tool_tick_verdict(const std::vector<ToolTickRow>& rows) {
  int n = 0, p99_ok = 0, ratio_ok = 0;
  double worst_p99 = -1, worst_ratio = -1;
  std::string at_p99, at_ratio;
  for (const ToolTickRow& row : rows)
    for (const TickSpread& t : row.tools) {
      ++n;
      const std::string where = row.scene + " r = " + fmt(t.radius_voxels, 0) + " voxels";
      const bool sane = t.ticks > 0 && std::isfinite(t.p99_us) && std::isfinite(t.median_us) && t.median_us > 0 &&
                        row.point.median_us > 0 && std::isfinite(row.point.median_us);
      const double ratio = sane ? t.median_us / row.point.median_us : HUGE_VAL;
      const double p99 = sane ? t.p99_us : HUGE_VAL;
      if (p99 <= kToolP99LimitUs) ++p99_ok;
      if (ratio <= kToolMedianRatioLimit) ++ratio_ok;
      if (p99 > worst_p99) worst_p99 = p99, at_p99 = where;
      if (ratio > worst_ratio) worst_ratio = ratio, at_ratio = where;
    }
  std::ostringstream s;
  s << "tool ticks: p99 <= " << fmt(kToolP99LimitUs, 0) << " us on " << p99_ok << " of " << n << ", median <= "
    << fmt(kToolMedianRatioLimit, 0) << " x the point's on " << ratio_ok << " of " << n;
  if (n > 0)
    s << " (worst p99: " << at_p99 << " " << fmt(worst_p99, 2) << " us; worst median ratio: " << at_ratio << " "
      << fmt(worst_ratio, 1) << " x)";
  s << ": " << (n > 0 && p99_ok == n && ratio_ok == n ? "PASS" : "FAIL");
  return s.str();
}

}  // namespace isotouch::bench
