// picture.h - pictures of a volume and of a run: the compute ray caster's frame written
// as a PNG (libpng, through the one output writer), the camera that shows a volume the
// right way up, the probe's overlays, and the run report's picture.
//
// Frames: pictures are drawn in grid-world [m] (core::Grid); the orbit camera's angles
// are physical (engine::OrbitCamera: azimuth 0 looks at the face of an LPS head from the
// front, +z physical up); TraceRow (sim/headless.h) is grid-world.
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/sim/headless.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/io/scene.h"
#include "isotouch/engine/volume.h"

namespace isotouch::run {

/// Writes an RGBA8 image (R in the low byte, rows top to bottom) as an 8-bit RGB PNG with
/// libpng, through PATH.tmp-PID and rename(2): never a half file.
/// @throws std::runtime_error naming the path and libpng's or the OS's message.
void write_png(const std::string& path, int width, int height, const std::vector<std::uint32_t>& rgba);

/// The scene's volume, as `isotouch run` loads it (file, or the synthetic shape).
engine::Volume load_scene_volume(const io::Scene& scene);
/// The ray caster's field of a volume at the scene's isovalue: background = the value
/// `isotouch run` publishes outside the grid (core::Isosurface::outside_value of the range).
engine::RaycastField scene_raycast_field(const io::Scene& scene, const engine::Volume& vol);

/// The orbit camera that shows `vol` the right way up: physical +z (superior) up, the eye
/// anterior (-y), turned into the grid frame by the volume's direction matrix. A volume stored
/// upside down shows upright when its header's direction says so; no file is special.
engine::OrbitCamera default_camera(const engine::Volume& vol);

/// A physical (LPS) direction in patient words: "superior", "inferior", "left", "right",
/// "anterior", "posterior" along an axis; "(x, y, z) LPS" otherwise.
std::string patient_axis(const core::Vec3& phys);

/// Turns the picture by quarter turns about the camera's front axis: up' = front x up per
/// turn (superior up with the eye anterior: the patient's right comes up).
void roll_camera(engine::OrbitCamera& cam, int quarter_turns);

/// What one picture shows and how.
struct PictureRequest {
  int width = 640, height = 640;
  engine::OrbitCamera camera;               ///< used unless `view` is set
  std::optional<engine::CameraView> view;   ///< an explicit grid-world camera
  engine::RaycastStyle style;
  std::vector<gpu::RaycastPrim> prims;      ///< overlays, grid-world [m]
  bool cpu = false;                         ///< the CPU reference instead of the GPU
};

/// Renders `field` and writes `out_png` (the sculpt scene calls it for before and after).
/// `direction`: the volume's D (for the orbit camera's physical angles).
/// @return the frame (image, depth, timings); throws on a Vulkan or PNG failure.
engine::RaycastImage render_picture(engine::VulkanContext* vk, const engine::RaycastField& field,
                                    const std::array<double, 9>& direction, const PictureRequest& req,
                                    const std::string& out_png);

/// The probe at one tick, grid-world: HIP (yellow sphere, seen through the surface),
/// VHIP (green sphere), the virtual plane (translucent cyan disc through the VHIP, normal
/// along the force; none without force) and the force (red arrow from the VHIP, length
/// |F| / force_limit x 12 size units). `size_m`: the size unit [m] (probe_size_m).
std::vector<gpu::RaycastPrim> probe_prims(const sim::TraceRow& row, double force_limit_n, double size_m);
/// A size unit for overlays: 0.6 x the largest voxel spacing, at least 0.6 mm [m].
double probe_size_m(const core::Grid& grid);

/// Result of render_run_picture: "" error when written; caption says what the colours mean.
struct RunPicture {
  std::string error;    ///< why no picture was written ("" if written)
  std::string caption;  ///< e.g. "contact points coloured by |F| from 0 N (blue) to 3.3 N (red) ..."
  std::string up;       ///< the picture's up in patient axes (patient_axis), e.g. "superior"
  double gpu_ms = -1;
};

/// The run report's picture: the isosurface around the contact, the HIP's path (thin grey,
/// seen through the surface), the contact points (VHIP at contact ticks) coloured by |F|
/// (blue 0 -> green -> yellow -> red at the run's max |F|), and the probe at the tick of
/// the largest force. Camera: looking against the mean contact force (from outside the
/// surface) at the contact points' centroid, physical +z up (anterior up when looking along z). Never throws: a failure
/// (no Vulkan device, unwritable path) comes back in RunPicture::error.
/// @param vol   the run's volume (grid, values, direction D)
/// @param field the published snapshot (its `background` is used; values from `vol`)
/// @param trace the run's ticks, grid-world (as run_headless returns them)
/// @param vk    a Vulkan context to reuse, or null to create one on `device` (kCpuDevice:
///              none, the CPU ray caster draws it)
RunPicture render_run_picture(const io::Scene& scene, const engine::Volume& vol, const core::SampleField& field,
                              const std::vector<sim::TraceRow>& trace, const std::string& out_png,
                              engine::VulkanContext* vk = nullptr, const std::string& device = "",
                              int width = 800, int height = 600);

}  // namespace isotouch::run
