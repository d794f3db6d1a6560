// overview.h - the run's overview picture: the whole object as `isotouch render` draws it
// (anatomical up from the volume's direction matrix), with the probe's path drawn on it.
//
// Frames: the trace is grid-world [m] (sim::TraceRow); the camera's angles are physical
// (LPS for medical images: +z superior), turned into the grid frame by the volume's D.
#pragma once
#include <array>
#include <string>
#include <vector>

#include "isotouch/core/isosurface.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/engine/volume.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/picture.h"
#include "isotouch/sim/headless.h"

namespace isotouch::run {

/// The overview's file name in a run folder.
inline constexpr const char* kOverviewFile = "overview.png";

/// The overview's camera, grid-world: `isotouch render`'s angles (run::default_camera:
/// physical +z up, the eye anterior, 10 deg above) framing the object (run::frame_object: the
/// box of its finite voxels inside `iso`, stray specks left out) as `isotouch render` does;
/// the whole volume's view when no voxel is inside.
engine::CameraView overview_view(const engine::Volume& vol, const core::Isosurface& iso);

/// The probe's path colour in the overview (linear RGB 0..1): magenta, seen through the surface.
inline constexpr std::array<float, 3> kOverviewPathRgb{1.0f, 0.1f, 1.0f};

/// Draws the overview: the isosurface at the scene's isovalue seen whole from overview_view,
/// the HIP's path (grid-world, at most 200 segments, drawn through the surface in
/// kOverviewPathRgb, about 1 % of the volume's size wide) and the first contact (a white dot).
/// Never throws: a failure comes back in RunPicture::error. RunPicture::up names the
/// physical axis shown up (patient_axis: "superior" for the default camera).
/// @param field the published snapshot (its `background` is used; values from `vol`)
/// @param vk    a Vulkan context to reuse, or null to create one on `device` (kCpuDevice: the
///              CPU ray caster)
RunPicture render_overview(const io::Scene& scene, const engine::Volume& vol, const core::SampleField& field,
                           const std::vector<sim::TraceRow>& trace, const std::string& out_png,
                           engine::VulkanContext* vk = nullptr, const std::string& device = "", int width = 640,
                           int height = 640);

/// report.md's sentence on the overview, e.g. "overview.png: the whole object seen from the
/// anterior, superior up, the probe's path in magenta." (from RunPicture::up and the camera).
std::string overview_sentence(const RunPicture& pic);

}  // namespace isotouch::run
