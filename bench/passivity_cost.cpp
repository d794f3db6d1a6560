#include "isotouch/bench/passivity_cost.h"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>

#include "isotouch/servo/live_passivity.h"
#include "isotouch/servo/port_passivity.h"

namespace isotouch::bench {

namespace {
/// Median over `reps` runs of the ns per tick of `tick(k, x, f_want)` over the stroke.
template <class Tick>
double ns_per_tick(const std::vector<core::Vec3>& hips, long ticks, int reps, Tick&& make_and_run) {
  if (hips.empty() || ticks <= 0 || reps <= 0) return 0;
  std::vector<double> ns;
  volatile double sink = 0;
  for (int r = 0; r < reps; ++r) {
    auto tick = make_and_run();
    const std::size_t lag = std::min<std::size_t>(100, hips.size() - 1);
    std::size_t i = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; k < ticks; ++k) {
      const core::Vec3& x = hips[i];
      const core::Vec3& behind = hips[i >= lag ? i - lag : i + hips.size() - lag];
      i = i + 1 == hips.size() ? 0 : i + 1;
      sink = sink + tick(k, x, (behind - x) * 800.0).x;
    }
    ns.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                 double(ticks));
  }
  std::nth_element(ns.begin(), ns.begin() + long(ns.size() / 2), ns.end());
  return ns[ns.size() / 2];
}
}  // namespace

double port_passivity_ns_per_tick(const std::vector<core::Vec3>& hips, long ticks, int reps) {
  return ns_per_tick(hips, ticks, reps, [] {
    return [pc = servo::PortPassivity(true, 40, 10)](long k, const core::Vec3& x, const core::Vec3& f) mutable {
      return pc.step(double(k) * 1e-3, x, f);
    };
  });
}

double live_passivity_ns_per_tick(const std::vector<core::Vec3>& hips, long ticks, int reps) {
  return ns_per_tick(hips, ticks, reps, [] {
    auto stage = std::make_unique<servo::LivePassivity>();  // holds atomics: not movable
    stage->start(true, 40, 1e9, 1e-3);
    return [s = std::shared_ptr<servo::LivePassivity>(std::move(stage))](long k, const core::Vec3& x,
                                                                        const core::Vec3& f) {
      // The device's clock at 1 kHz, in us (wraps as a uint32 does); the servo's in ns.
      const core::Vec3 out = s->step(k * 1000000, std::uint32_t(1 + k * 1000), x, f);
      s->sent(out);
      return out;
    };
  });
}

}  // namespace isotouch::bench
