#include "isotouch/run/scene_script.h"

#include <cmath>
#include <ostream>

#include "isotouch/eval/touch_plan.h"
#include "isotouch/run/text.h"

namespace isotouch::run {

sim::TouchScript scene_script(const io::Scene& scene, const core::SampleField& truth, const servo::HriParams& hri,
                              RunMetrics& m, std::ostream& log) {
  m.plan = scene.script.plan;
  if (scene.script.plan != "surface") {
    m.plan_press_depth_m = m.plan_min_press_depth_m = scene.script.press_depth_m;
    return sim::make_touch_script(truth, hri, scene.script);
  }
  eval::TouchPlanOptions o;
  o.force_fraction = scene.script.press_force_fraction;
  eval::TouchPlan plan = eval::plan_touch(truth, hri, scene.device, scene.script, o);
  m.plan_press_depth_m = plan.press_depth_m;
  m.plan_min_press_depth_m = plan.min_press_depth_m;
  m.plan_force_depth_m = plan.force_depth_m;
  m.plan_min_wall_m = plan.min_thickness_m;
  m.plan_stroke_length_m = plan.stroke_length_m;
  log << "plan     on the true isosurface: pressed " << fmt(plan.press_depth_m * 1e3, 3) << " mm along the normal ("
      << fmt(plan.force_depth_m * 1e3, 3) << " mm holds " << fmt(o.force_fraction, 3) << " of the "
      << fmt(hri.force_limit_n, 3) << " N limit; thinnest wall under the stroke "
      << (std::isfinite(plan.min_thickness_m) ? fmt(plan.min_thickness_m * 1e3, 3) + " mm" : std::string("not reached"))
      << "), stroke " << fmt(plan.stroke_length_m * 1e3, 3) << " of " << fmt(scene.script.stroke_length_m * 1e3, 3)
      << " mm walked on the surface, starting " << fmt(plan.direction_deg, 3) << " deg from script.stroke_direction ("
      << plan.directions_tried << " direction(s) tried)\n";
  return std::move(plan.script);
}

}  // namespace isotouch::run
