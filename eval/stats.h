// stats.h - the one place for the summary statistics the reports and benchmarks print.
#pragma once
#include <vector>

namespace isotouch::eval {

/// Median of `v` (mean of the middle two for an even count); NaN values are dropped;
/// NaN if nothing is left.
double median(std::vector<double> v);

/// Nearest-rank percentile: the smallest value v of `x` such that at least q * n values
/// are <= v (q in [0, 1]; q = 0 gives the minimum). NaN values are dropped; NaN if none is left.
double percentile(std::vector<double> x, double q);

}  // namespace isotouch::eval
