// burr.h - the tool the sculpting app lets a person feel is the tool that cuts: a carve or
// drill brush of radius r is felt as the spherical tool of radius r (servo::HriRenderer's
// tool_radius_m), the brush cutting r plus at most half a voxel around the tool's centre
// (--point-probe keeps the point of old, for comparison). FeltTool carries a radius the
// window's thread chooses into the servo thread; DrillWatch measures what a drill left (the
// channel, eval/drill_channel.h) and how the tool came out of it (the lift's inward force).
#pragma once
#include <atomic>
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "isotouch/apps/sculpt/tools.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"
#include "isotouch/engine/volume.h"
#include "isotouch/servo/hri.h"

namespace isotouch::sculpt {

/// The radius the tool is felt with [m, world]: the brush's for carve and drill, 0 (the
/// point) for add and smooth, and for every tool with `point_probe`.
double felt_radius_m(const ToolState& t, bool point_probe);

/// The margin the cutting brush has beyond the felt sphere [m]: half the largest voxel
/// spacing (what `isotouch run` scenes use, run::tool_brush_margin_m).
double cut_margin_m(const engine::Volume& vol);

/// The tool's brush parameters for a felt radius `felt_m` (0: the point): the brush is
/// r + `margin_m` wide, full strength out to r and fading over the margin (what touches
/// cuts); the point keeps the brush of old (the tool's radius, falloff 0.5).
void fit_brush_to_felt_tool(ToolState& t, double felt_m, double margin_m);

/// The servo's renderer with a tool radius chosen by another thread: want() stores it (any
/// thread, lock-free); the next tick applies it on the servo thread before it renders
/// (servo::HriRenderer::set_tool_radius: the contact re-seated, the force eased from the
/// one sent, no step). `fixed()` ignores every want() (a recorded session: the recording
/// replays with one radius).
class FeltTool final : public servo::Renderer {
 public:
  explicit FeltTool(servo::HriRenderer& hri)
      : hri_(hri), wanted_(hri.params().tool_radius_m), applied_(hri.params().tool_radius_m) {}
  const char* name() const override { return hri_.name(); }
  void reset() override { hri_.reset(); }
  using servo::Renderer::tick;
  servo::HriTick tick(const core::FieldView& field, const core::Vec3& hip_world_m, double dt_s) override;
  /// The radius from the next tick on [m]; ignored while fixed().
  void want(double radius_m) {
    if (!fixed_) wanted_.store(radius_m, std::memory_order_relaxed);
  }
  void fix() { fixed_ = true; }
  bool fixed() const { return fixed_; }
  /// The radius the servo thread renders now [m] (the last one applied; 0: the point).
  double applied_m() const { return applied_.load(std::memory_order_relaxed); }
  /// Radius changes applied by the servo thread so far.
  long changes() const { return changes_.load(std::memory_order_relaxed); }

 private:
  servo::HriRenderer& hri_;
  std::atomic<double> wanted_, applied_;
  std::atomic<long> changes_{0};
  bool fixed_ = false;
};

/// `scene_text` (a scene file's JSON) with its servo's tool set to `radius_m` (0: the point),
/// so that a recording's replay renders the tool the session felt.
/// @throws std::runtime_error naming `name` when the text is not a JSON object.
std::string scene_text_with_tool(const std::string& scene_text, double radius_m, const std::string& name);

/// One servo tick as DrillWatch sees it (grid-world).
struct TickSample {
  double t_s = 0;
  core::Vec3 force_n, vhip_m;
  bool contact = false;
};

/// The app's drills: the burr centre's path while the drill's button is down in contact, the
/// volume before the first of them, and the lift after the last (button up): the largest
/// force component into the hole (along the drilling direction) while in contact.
class DrillWatch {
 public:
  /// One frame, before its brush is submitted: `drilling` (the drill tool's button down),
  /// the felt burr's radius `burr_m` (the brush's for the point) and the cutting brush's
  /// `cut_m` [m]; `volume_now` (the edited voxels as applied so far) is called once, at
  /// the first drill's first frame.
  void press(bool drilling, double burr_m, double cut_m, const std::function<engine::Volume()>& volume_now);
  /// The ticks since the last frame (every tick on a simulated clock; the frame's one
  /// observed tick in real time).
  void ticks(const std::vector<TickSample>& ticks);
  bool drilled() const { return !centres_.empty(); }
  /// The drilling direction: against the mean force while drilling (unit; grid-world).
  core::Vec3 axis() const;
  /// Prints the "drill    ..." lines: the burr and the cutting brush (its margin), the
  /// channel's narrowest open radius measured on `after` (the edited volume once every edit
  /// is applied) against the burr, the lift's largest inward force against `force_limit_n`
  /// and how many ticks it was taken from. Nothing when no drill touched.
  void report(std::ostream& log, const engine::Volume& after, const core::Isosurface& iso,
              double force_limit_n) const;

 private:
  engine::Volume before_;
  std::vector<core::Vec3> centres_;
  core::Vec3 force_sum_;  // the force while drilling in contact [N]
  bool was_drilling_ = false;
  bool lifting_ = false;
  bool drilling_ = false;
  double burr_m_ = 0, cut_m_ = 0;
  long lift_ticks_ = 0, lift_contact_ticks_ = 0, lift_inward_ticks_ = 0, samples_ = 0;
  double lift_max_inward_n_ = 0;
};

}  // namespace isotouch::sculpt
