// channel_section.h - a drilled channel cut open, drawn from the voxels after drilling
// (not rendered: the trilinear field sampled on two planes), for drill scenes' reports.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"
#include "isotouch/engine/volume.h"

namespace isotouch::run {

/// Where the channel is cut, grid-world [m].
struct ChannelCut {
  core::Vec3 centre_m;         ///< the burr path's centre on the narrowest slice (eval::ChannelFigures::min_centre_m)
  core::Vec3 axis;             ///< the drilling direction (unit)
  double burr_radius_m = 0;    ///< the burr's radius (the felt tool's, else the brush's)
  double open_radius_m = 0;    ///< the narrowest open radius measured there
};

/// Panel colours of channel_section.png (RGBA8, R in the low byte).
inline constexpr unsigned kSectionMaterial = 0xffc8dce6u;  ///< material after drilling (bone)
inline constexpr unsigned kSectionRemoved = 0xff288ce6u;   ///< material before, removed by the drill (orange)
inline constexpr unsigned kSectionEmpty = 0xff342c28u;     ///< empty before and after
inline constexpr unsigned kSectionBurr = 0xff50c83cu;      ///< the burr's radius (green)
inline constexpr unsigned kSectionOpen = 0xff2828dcu;      ///< the narrowest open radius (red)

/// The picture draw_channel_section writes: `width` x `height` RGBA8 pixels, rows top to bottom.
struct ChannelSectionImage {
  int width = 0, height = 0;
  std::vector<std::uint32_t> rgba;
};

/// channel_section.png's pixels (see draw_channel_section); empty (width 0) without a burr
/// radius or with a panel under 16 pixels.
ChannelSectionImage channel_section_image(const engine::Volume& before, const engine::Volume& after,
                                          const core::Isosurface& iso, const ChannelCut& cut, int panel = 320);

/// channel_section.png: two square panels of `panel` pixels side by side, each 5 burr radii
/// wide around `cut.centre_m`. Left: the cross-section perpendicular to the axis at the
/// narrowest slice, with the burr's circle (green) and the measured open radius (red).
/// Right: the section along the channel (the axis pointing down, the same scale), the burr's
/// width as two green lines and the narrowest slice as a red bar of the open diameter.
/// Material after drilling is bone-white, what the drill removed orange (material of `before`,
/// outside in `after`), empty dark. Written through the one output writer (write_png).
/// @return "" or why it was not written (never throws).
std::string draw_channel_section(const engine::Volume& before, const engine::Volume& after, const core::Isosurface& iso,
                                 const ChannelCut& cut, const std::string& out_png, int panel = 320);

}  // namespace isotouch::run
