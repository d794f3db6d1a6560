// drill_figure.h - one picture that shows where a drill went in and what it removed.
#pragma once
#include <string>

#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"
#include "isotouch/engine/volume.h"
#include "isotouch/engine/vk_context.h"

namespace isotouch::run {

/// Where the drill went in, grid-world [m].
struct DrillSite {
  core::Vec3 point_m;       ///< the first contact point (on the unedited surface)
  core::Vec3 outward;       ///< unit surface normal there, out of the object
  double brush_radius_m = 0;
};

/// Panel and inset sizes of drill.png [pixels].
struct DrillFigureLayout {
  int panel_width = 640, panel_height = 480;  ///< each of before / after
  int inset = 230;                             ///< the zoomed square in each panel's top-right corner
  int gap = 8;                                 ///< between the panels
  double wide_half_width_m = 0.045;            ///< half the width the wide view shows at the site
  double zoom_half_width_brush = 3.0;          ///< the inset shows this many brush radii each side
};

/// drill.png: before (left) and after (right) side by side, the same cameras: each panel a
/// wide view of the site from outside (along `outward`, the volume's superior side up) with
/// a ring of markers (2 brush radii) around the site, and a zoomed inset of the site in the
/// top-right corner (white frame). Rendered by the compute ray caster on `vk` (or the CPU
/// reference when null), written through the one output writer.
/// @return "" or why the picture was not written (never throws).
std::string draw_drill_figure(engine::VulkanContext* vk, const engine::Volume& before, const engine::Volume& after,
                              const core::Isosurface& iso, const DrillSite& site, const std::string& out_png,
                              const DrillFigureLayout& layout = {});

}  // namespace isotouch::run
