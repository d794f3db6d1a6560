// app_felt_tool.cpp - isotouch-sculpt's felt tool: the brush felt as a sphere (burr.h, sculpt_app.h).

#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

// --- the felt tool: the carve or drill brush is felt as a sphere of its radius (burr.h) ----

namespace {

/// A radius as a recording's scene text gives it back to replay (radius_mm, parsed): the
/// same bits, so that a recorded session replays identically.
double as_recorded(double radius_m) { return 1e-3 * (1e3 * radius_m); }

}  // namespace

/// The tool: carried over, or the scene's tool radius where it gives one, else sized to
/// the voxels.
void Sculpt::choose_tool() {
  if (o.carried && o.carried->tool) tool = *o.carried->tool;
  tool.targets = session::default_targets(vol, live.iso);
  if (o.carried && o.carried->tool) return;
  const double sp = std::max({vol.grid.spacing_m.x, vol.grid.spacing_m.y, vol.grid.spacing_m.z});
  tool.radius_m = scene.hri.tool_radius_m > 0 ? scene.hri.tool_radius_m : std::max(4e-3, 2.5 * sp);
}

/// The scene's servo with the tool's felt radius; the point where the scene keeps it or
/// renders what the sphere does not (the paper variant, friction, force shading).
servo::HriParams Sculpt::felt_params() {
  servo::HriParams p = scene.hri;
  const bool sphere_ok = p.variant == servo::Variant::kRobust && !p.friction.any() && !p.force_shading && !scene.point_probe;
  felt_m = sphere_ok ? as_recorded(felt_radius_m(tool, o.point_probe)) : 0.0;
  p.tool_radius_m = felt_m;
  if (!sphere_ok) felt_m = -1;  // never a sphere in this session
  // The app's brushes come once a frame: an edit's material took a frame to cut.
  if (o.sim_clock) p.edit_period_s = double(std::max(1L, std::lround(o.sim_frame_ms * 1e-3 * p.rate_hz))) / p.rate_hz;
  return p;
}

/// Each frame: the servo feels the tool's radius (a recorded session the one it began
/// with) and the brush fits what is felt.
void Sculpt::fit_felt_tool() {
  if (felt_m >= 0 && !felt->fixed()) {
    felt_m = as_recorded(felt_radius_m(tool, o.point_probe));
    felt->want(felt_m);
  }
  fit_brush_to_felt_tool(tool, std::max(0.0, felt_m), cut_margin_m(vol));
}

/// The ticks since the last frame for the drill's figures: every tick on the simulated
/// clock, else the frame's observed one.
void Sculpt::watch_drill(const std::vector<sim::TraceRow>& rows, const session::Observed& obs) {
  std::vector<TickSample> ticks;
  for (const sim::TraceRow& r : rows) ticks.push_back({r.t_s, r.force_n, r.vhip_m, r.contact});
  if (!o.sim_clock && obs.tick > last_watched_tick) {
    ticks.push_back({double(obs.tick) / scene.hri.rate_hz, obs.force_n, obs.vhip_m, obs.contact});
    last_watched_tick = obs.tick;
  }
  drill.ticks(ticks);
}

void Sculpt::print_felt_tool() {
  const double margin = cut_margin_m(vol);
  if (felt_m < 0)
    log << "sculpt   tool felt as the point: the scene keeps it (servo.tool.point, the paper variant, friction or force shading)\n";
  else if (o.point_probe)
    log << "sculpt   tool felt as the point (--point-probe); the brush cuts its own radius around it\n";
  else
    log << "sculpt   tool felt as a sphere of the carve or drill brush's radius (" << fixed(felt_m * 1e3, 2)
        << " mm now; add and smooth: the point); the brush cuts to its surface and fades over "
        << fixed(margin * 1e3, 2) << " mm (half a voxel) beyond it\n";
  if (felt->fixed() && felt_m >= 0)
    log << "sculpt   --record: the tool stays as felt now for the whole session (the recording replays with one "
           "tool); the brush follows radius changes\n";
}

}  // namespace isotouch::sculpt::detail
