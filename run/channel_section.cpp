#include "isotouch/run/channel_section.h"

#include <cmath>
#include <cstdint>
#include <exception>
#include <vector>

#include "isotouch/eval/drill_channel.h"
#include "isotouch/run/picture.h"

namespace isotouch::run {

namespace {

using core::Vec3;

/// One panel's plane: pixel (i, j) of `n` is centre + h (i - n/2 + 1/2) px + v (j - n/2 + 1/2) px.
struct Plane {
  Vec3 centre, h, v;  // h, v unit; v downward in the picture
  double px = 0;      // metres per pixel
};

/// The pixel colour of the field at x: after, before and the overlays are the caller's.
unsigned material_colour(const engine::Volume& before, const engine::Volume& after, const core::Isosurface& iso,
                         const Vec3& x) {
  if (iso.contains(eval::volume_trilinear(after, x))) return kSectionMaterial;
  return iso.contains(eval::volume_trilinear(before, x)) ? kSectionRemoved : kSectionEmpty;
}

/// Draws one panel into `rgba` (row stride `stride`) at column `x0`; `overlay` gives an
/// overlay colour for a point's plane coordinates (a, b) [m] and the pixel size, or 0.
template <class Overlay>
void draw_panel(std::vector<std::uint32_t>& rgba, int stride, int x0, int n, const Plane& pl,
                const engine::Volume& before, const engine::Volume& after, const core::Isosurface& iso,
                const Overlay& overlay) {
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double a = (i - 0.5 * n + 0.5) * pl.px, b = (j - 0.5 * n + 0.5) * pl.px;
      const unsigned over = overlay(a, b, pl.px);
      rgba[std::size_t(j) * std::size_t(stride) + std::size_t(x0 + i)] =
          over != 0 ? over : material_colour(before, after, iso, pl.centre + pl.h * a + pl.v * b);
    }
}

}  // namespace

ChannelSectionImage channel_section_image(const engine::Volume& before, const engine::Volume& after,
                                          const core::Isosurface& iso, const ChannelCut& cut, int panel) {
  ChannelSectionImage img;
  const double r = cut.burr_radius_m, open = cut.open_radius_m;
  if (!(r > 0) || !(panel >= 16)) return img;
  const Vec3 axis = core::normalized_or(cut.axis, Vec3{0, 0, -1});
  const Vec3 any = std::abs(axis.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  const Vec3 u = core::normalized_or(any - axis * core::dot(any, axis), Vec3{0, 1, 0});
  const Vec3 w = core::cross(axis, u);
  const double px = 5.0 * r / panel;
  const int gap = 8;
  img.width = 2 * panel + gap;
  img.height = panel;
  img.rgba.assign(std::size_t(img.width) * std::size_t(panel), 0xffffffffu);
  auto ring = [](double rho, double radius, double pixel) { return std::abs(rho - radius) < 0.75 * pixel; };
  // Across: the burr's circle and the open radius's.
  draw_panel(img.rgba, img.width, 0, panel, Plane{cut.centre_m, u, w, px}, before, after, iso,
             [&](double a, double b, double pixel) -> unsigned {
               const double rho = std::hypot(a, b);
               if (ring(rho, open, pixel)) return kSectionOpen;
               if (ring(rho, r, pixel)) return kSectionBurr;
               return 0;
             });
  // Along: the axis down the picture, the burr's width, the narrowest slice's diameter.
  draw_panel(img.rgba, img.width, panel + gap, panel, Plane{cut.centre_m, u, axis, px}, before, after, iso,
             [&](double a, double b, double pixel) -> unsigned {
               if (std::abs(b) < pixel && std::abs(a) <= open) return kSectionOpen;
               if (ring(std::abs(a), r, pixel)) return kSectionBurr;
               return 0;
             });
  return img;
}

std::string draw_channel_section(const engine::Volume& before, const engine::Volume& after, const core::Isosurface& iso,
                                 const ChannelCut& cut, const std::string& out_png, int panel) {
  try {
    const ChannelSectionImage img = channel_section_image(before, after, iso, cut, panel);
    if (img.width == 0) return "no burr radius or a panel under 16 pixels";
    write_png(out_png, img.width, img.height, img.rgba);
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

}  // namespace isotouch::run
