// stats.cpp - see stats.h.
#include "isotouch/eval/stats.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace isotouch::eval {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
void drop_nan(std::vector<double>& v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return std::isnan(x); }), v.end());
}
}  // namespace

double median(std::vector<double> v) {
  drop_nan(v);
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double percentile(std::vector<double> x, double q) {
  drop_nan(x);
  if (x.empty() || std::isnan(q)) return kNaN;
  std::sort(x.begin(), x.end());
  q = std::clamp(q, 0.0, 1.0);
  const double n = double(x.size());
  // Rank k (1-based) = ceil(q n); the 1e-9 keeps 0.99 * 100 = 99.000000000000014 at 99.
  std::size_t k = std::size_t(std::max(1.0, std::ceil(q * n - 1e-9)));
  k = std::min(k, x.size());
  return x[k - 1];
}

}  // namespace isotouch::eval
