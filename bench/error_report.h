// error_report.h - `isotouch report`: error against run time, every algorithm and option.
#pragma once
#include <iosfwd>
#include <string>
#include <vector>

namespace isotouch::bench {

struct ReportOptions {
  std::vector<std::string> scenes{"sphere", "box", "three-spheres", "knot", "head", "chest"};
  std::string out_dir = "out/report";
  std::string device;  ///< Vulkan device for the gradient pass ("" = default)
};

/// Sweep algorithm x n in {1, 2, 5, 10, 20, 50} x options x scene along the same recorded
/// strokes; write DIR/error_vs_time.csv, DIR/error_vs_time.png and DIR/error_vs_time.md
/// (Pareto front per scene, force steps of the §3.3 remedies on the knot).
int run_report(const ReportOptions& options, std::ostream& log);

}  // namespace isotouch::bench
