// tool_ticks.cpp - see tool_ticks.h.
#include "isotouch/service/tool_ticks.h"

#include <algorithm>

namespace isotouch::service {

std::chrono::steady_clock::time_point next_tick(std::chrono::steady_clock::time_point due,
                                                std::chrono::steady_clock::time_point now,
                                                std::chrono::steady_clock::duration period) {
  return (now > due + period ? now : due) + period;
}

double tool_dt(double since_s, double period_s) { return std::clamp(since_s, 0.0, 2 * period_s); }

bool StrokeGap::out_of_contact(double dt_s) {
  apart_s_ += dt_s;
  if (apart_s_ + 1e-9 < kStrokeGapS) return false;  // 6 ticks of 1/60 s sum to a hair under 0.1
  apart_s_ = 0;
  return true;
}

}  // namespace isotouch::service
