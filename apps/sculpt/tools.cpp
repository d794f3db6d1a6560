#include "isotouch/apps/sculpt/tools.h"

#include <algorithm>
#include <cmath>

namespace isotouch::sculpt {

std::optional<session::BrushKind> tool_from_name(const std::string& name) {
  using K = session::BrushKind;
  if (name == "add") return K::kAdd;
  if (name == "carve") return K::kCarve;
  if (name == "smooth") return K::kSmooth;
  if (name == "drill") return K::kDrill;
  return std::nullopt;
}

void step_radius(ToolState& t, bool up) {
  t.radius_m = up ? std::min(kMaxRadiusM, t.radius_m * 1.25) : std::max(kMinRadiusM, t.radius_m / 1.25);
}

void step_strength(ToolState& t, bool up) {
  t.strength = up ? std::min(kMaxStrength, t.strength * 1.25) : std::max(kMinStrength, t.strength / 1.25);
}

session::Brush make_tool_brush(const ToolState& t, const core::Vec3& centre_m, double force_n, double dt_s) {
  session::Brush b;
  b.kind = t.kind;
  b.centre_m = centre_m;
  b.radius_m = t.radius_m + t.cut_margin_m;
  b.falloff = t.falloff;
  b.targets = t.targets;
  const double span = std::max(1e-6, std::fabs(double(t.targets.material) - double(t.targets.empty)));
  switch (t.kind) {
    case session::BrushKind::kAdd:
    case session::BrushKind::kCarve: b.strength = t.strength * span; break;
    case session::BrushKind::kSmooth: b.strength = std::clamp(t.strength, 0.0, 1.0); break;
    case session::BrushKind::kDrill:
      b.strength = 1.0;
      b.force_n = std::isfinite(force_n) ? force_n : 0.0;
      b.force_threshold_n = 0.2;
      b.rate = 4.0 * t.strength * span;  // [value / (N s)]: strength 0.25 removes |span| in 1 s at 1.2 N
      b.dt_s = std::clamp(dt_s, 1e-4, 0.1);
      break;
  }
  return b;
}

void Stroke::frame(bool down, bool contact, const ToolState& tool, const core::Vec3& vhip_m, double force_n,
                   double dt_s, std::vector<session::EditEvent>& out) {
  using K = session::EditEvent::Kind;
  if (down && contact) {
    if (!open_) {
      session::EditEvent b;
      b.kind = K::kBeginStroke;
      out.push_back(b);
      open_ = true;
    }
    session::EditEvent e;
    e.kind = K::kBrush;
    e.brush = make_tool_brush(tool, vhip_m, force_n, dt_s);
    out.push_back(e);
  } else if (!down && open_) {
    session::EditEvent e;
    e.kind = K::kEndStroke;
    out.push_back(e);
    open_ = false;
  }
}

}  // namespace isotouch::sculpt
