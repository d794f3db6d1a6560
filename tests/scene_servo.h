// scene_servo.h - test helper: the HRI servo the shipped scenes run (K = 800 N/m, limit 3.3 N,
// B = 1 N s/m, secant intersection, 20 ms recovery ramp), for tests that judge the renderer
// on generated volumes with the settings a user gets.
#pragma once
#include "isotouch/servo/hri.h"

namespace isotouch::test {

/// The shipped scenes' servo at level tau = 0 (the generated fields hold value - isovalue);
/// everything else (plane update period, tool radius, edit period) as HriParams has it.
inline servo::HriParams scene_servo() {
  servo::HriParams p;
  p.tau = 0;
  p.stiffness_n_per_m = 800;     // [N/m]
  p.damping_n_s_per_m = 1.0;     // [N s/m]
  p.force_limit_n = 3.3;         // [N]
  p.intersection = servo::Intersection::kSecant;
  p.recovery_time_s = 0.02;      // [s]
  return p;
}

}  // namespace isotouch::test
