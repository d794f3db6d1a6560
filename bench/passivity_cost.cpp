#include "isotouch/bench/passivity_cost.h"

#include <algorithm>
#include <chrono>

#include "isotouch/servo/port_passivity.h"

namespace isotouch::bench {

double port_passivity_ns_per_tick(const std::vector<core::Vec3>& hips, long ticks, int reps) {
  if (hips.empty() || ticks <= 0 || reps <= 0) return 0;
  std::vector<double> ns;
  volatile double sink = 0;
  for (int r = 0; r < reps; ++r) {
    servo::PortPassivity pc(true, 40, 10);
    const std::size_t lag = std::min<std::size_t>(100, hips.size() - 1);
    std::size_t i = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; k < ticks; ++k) {
      const core::Vec3& x = hips[i];
      const core::Vec3& behind = hips[i >= lag ? i - lag : i + hips.size() - lag];
      i = i + 1 == hips.size() ? 0 : i + 1;
      const core::Vec3 f = pc.step(double(k) * 1e-3, x, (behind - x) * 800.0);
      sink = sink + f.x;
    }
    ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                 double(ticks));
  }
  std::nth_element(ns.begin(), ns.begin() + long(ns.size() / 2), ns.end());
  return ns[ns.size() / 2];
}

}  // namespace isotouch::bench
