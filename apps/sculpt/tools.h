// tools.h - the sculpting tools (add, carve, smooth, drill), their radius and strength,
// and the stroke logic: while the button is held and the probe is in contact, one brush
// application per frame at the VHIP, grouped into one undo step per press.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "isotouch/session/brush.h"
#include "isotouch/session/edit_session.h"
#include "isotouch/core/vec3.h"

namespace isotouch::sculpt {

struct ToolState {
  session::BrushKind kind = session::BrushKind::kCarve;
  double radius_m = 4e-3;
  double strength = 0.25;  ///< add / carve: fraction of |material - empty| per application;
                           ///< smooth: the brush's strength in [0, 1]; drill: its rate scale
  session::BrushTargets targets;
  /// The brush's reach beyond radius_m [m] and its soft edge (session::Brush::falloff): a
  /// tool felt as a sphere cuts out to its surface and fades over a margin beyond it
  /// (fit_brush_to_felt_tool, burr.h); the point's brush is radius_m with falloff 0.5.
  double cut_margin_m = 0;
  double falloff = 0.5;
};

/// The radius and strength limits; the keys ([ ] - =) and the overlay's widgets keep to them.
inline constexpr double kMinRadiusM = 0.5e-3, kMaxRadiusM = 0.1;
inline constexpr double kMinStrength = 0.01, kMaxStrength = 1.0;
/// One key step: the radius or strength times 1.25 (`up`) or divided by it, within the limits.
void step_radius(ToolState& t, bool up);
void step_strength(ToolState& t, bool up);

/// "add", "carve", "smooth", "drill" -> kind; nullopt otherwise.
std::optional<session::BrushKind> tool_from_name(const std::string& name);

/// The brush one application of the tool makes at `centre_m` (grid-world; the felt tool's
/// centre), radius radius_m + cut_margin_m, the user pushing with |F| = `force_n` for `dt_s` seconds.
session::Brush make_tool_brush(const ToolState& t, const core::Vec3& centre_m, double force_n, double dt_s);

/// The stroke of one button press: begin on the first application, end on release.
class Stroke {
 public:
  /// One frame: `down` the button, `contact` the probe's. Appends the events to submit.
  void frame(bool down, bool contact, const ToolState& tool, const core::Vec3& vhip_m, double force_n, double dt_s,
             std::vector<session::EditEvent>& out);
  bool open() const { return open_; }

 private:
  bool open_ = false;
};

}  // namespace isotouch::sculpt
