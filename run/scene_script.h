// scene_script.h - the scripted hand of a scene: the ray script (sim/script.h) or the touch
// planned on the true isosurface (eval/touch_plan.h), as the scene's script.plan says.
#pragma once
#include <iosfwd>

#include "isotouch/core/sample_field.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/run_metrics.h"
#include "isotouch/servo/hri.h"
#include "isotouch/sim/script.h"

namespace isotouch::run {

/// The hand path of `scene` on `truth` (dense samples, grid-world [m]) for the renderer `hri`:
/// script.plan "ray" or "surface". The plan's figures go to `m` (RunMetrics::plan_*) and, for
/// "surface", one line to `log`. @throws std::runtime_error as sim::make_touch_script.
sim::TouchScript scene_script(const io::Scene& scene, const core::SampleField& truth, const servo::HriParams& hri,
                              RunMetrics& m, std::ostream& log);

}  // namespace isotouch::run
