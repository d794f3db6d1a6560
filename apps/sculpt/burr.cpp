#include "isotouch/apps/sculpt/burr.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "isotouch/eval/drill_channel.h"
#include "isotouch/run/scene_setup.h"

namespace isotouch::sculpt {

namespace {
std::string fixed(double v, int p) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(p) << v;
  return s.str();
}
}  // namespace

double felt_radius_m(const ToolState& t, bool point_probe) {
  const bool cuts = t.kind == session::BrushKind::kCarve || t.kind == session::BrushKind::kDrill;
  return cuts && !point_probe ? t.radius_m : 0.0;
}

double cut_margin_m(const engine::Volume& vol) { return run::tool_brush_margin_m(vol); }

void fit_brush_to_felt_tool(ToolState& t, double felt_m, double margin_m) {
  if (felt_m > 0) {
    t.cut_margin_m = margin_m;
    t.falloff = std::clamp(margin_m / (felt_m + margin_m), 1e-3, 1.0);
  } else {
    t.cut_margin_m = 0;
    t.falloff = 0.5;
  }
}

servo::HriTick FeltTool::tick(const core::FieldView& field, const core::Vec3& hip_world_m, double dt_s) {
  const double want = wanted_.load(std::memory_order_relaxed);
  if (want != hri_.params().tool_radius_m) {
    hri_.set_tool_radius(want);
    applied_.store(hri_.params().tool_radius_m, std::memory_order_relaxed);
    changes_.fetch_add(1, std::memory_order_relaxed);
  }
  return hri_.tick(field, hip_world_m, dt_s);
}

std::string scene_text_with_tool(const std::string& scene_text, double radius_m, const std::string& name) {
  nlohmann::ordered_json j = nlohmann::ordered_json::parse(scene_text, nullptr, false);
  if (!j.is_object()) throw std::runtime_error(name + ": not a JSON object: cannot record the tool felt");
  if (!j.contains("servo") || !j["servo"].is_object()) j["servo"] = nlohmann::ordered_json::object();
  if (radius_m > 0) j["servo"]["tool"] = {{"radius_mm", 1e3 * radius_m}};
  else j["servo"]["tool"] = {{"point", true}};
  return j.dump(2) + "\n";
}

core::Vec3 DrillWatch::axis() const { return core::normalized_or(force_sum_ * -1.0, core::Vec3{0, 0, -1}); }

void DrillWatch::press(bool drilling, double burr_m, double cut_m, const std::function<engine::Volume()>& volume_now) {
  if (drilling && !was_drilling_ && centres_.empty()) before_ = volume_now();  // before the first drill
  if (drilling) {
    lifting_ = false;
    burr_m_ = burr_m;
    cut_m_ = cut_m;
  } else if (was_drilling_) {
    lifting_ = true;  // the button came up: the lift begins
  }
  was_drilling_ = drilling;
  drilling_ = drilling;
}

void DrillWatch::ticks(const std::vector<TickSample>& ticks) {
  for (const TickSample& s : ticks) {
    ++samples_;
    if (drilling_ && s.contact) {
      centres_.push_back(s.vhip_m);
      force_sum_ = force_sum_ + s.force_n;
    }
    if (!lifting_) continue;
    ++lift_ticks_;
    if (!s.contact) continue;
    ++lift_contact_ticks_;
    const double inward = core::dot(s.force_n, axis());  // along the drilling direction: into the hole
    if (inward > 0) {
      ++lift_inward_ticks_;
      lift_max_inward_n_ = std::max(lift_max_inward_n_, inward);
    }
  }
}

void DrillWatch::report(std::ostream& log, const engine::Volume& after, const core::Isosurface& iso,
                        double force_limit_n) const {
  if (centres_.empty()) return;
  const double burr_m = burr_m_, cut_m = cut_m_;
  const core::Vec3 a = axis();
  const eval::ChannelFigures c = eval::measure_channel(before_, after, iso, centres_, a, burr_m);
  log << "drill    burr radius " << fixed(burr_m * 1e3, 3) << " mm, cutting brush " << fixed(cut_m * 1e3, 3)
      << " mm (margin " << fixed((cut_m - burr_m) * 1e3, 3) << " mm, "
      << fixed((cut_m - burr_m) / std::max({after.grid.spacing_m.x, after.grid.spacing_m.y, after.grid.spacing_m.z}), 2)
      << " voxel); axis [" << fixed(a.x, 4) << ", " << fixed(a.y, 4) << ", " << fixed(a.z, 4) << "]; "
      << centres_.size() << " drilling ticks in contact\n";
  if (c.measured)
    log << "drill    channel: narrowest open radius " << fixed(c.min_open_radius_m * 1e3, 3) << " mm ("
        << fixed(100 * c.min_fraction, 1) << " % of the burr) at " << fixed(c.min_at_depth_m * 1e3, 3)
        << " mm along the path, " << c.slices << " slices\n";
  else
    log << "drill    channel: not measured (the burr's path never crossed material of the volume before)\n";
  log << "drill    lift: " << lift_ticks_ << " ticks after the button came up, " << lift_contact_ticks_
      << " in contact, " << lift_inward_ticks_ << " pulling into the hole; lift_max_inward_force_n "
      << fixed(lift_max_inward_n_, 4) << " N (" << fixed(100 * lift_max_inward_n_ / force_limit_n, 1)
      << " % of the " << fixed(force_limit_n, 2) << " N limit; " << samples_ << " ticks sampled)\n";
}

}  // namespace isotouch::sculpt
