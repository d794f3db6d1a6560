// overview.cpp - the run's overview picture; see overview.h.
#include "isotouch/run/overview.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <utility>

#include "isotouch/run/object_box.h"
#include "isotouch/run/scene_setup.h"

namespace isotouch::run {
using core::finite;
using core::norm;
using core::Vec3;

engine::CameraView overview_view(const engine::Volume& vol, const core::Isosurface& iso) {
  return engine::orbit_view(vol.grid, vol.direction, frame_object(default_camera(vol), vol, iso));
}

namespace {

/// The path's segments (at most 200, seen through the surface) and a dot at the first contact.
std::vector<gpu::RaycastPrim> path_prims(const std::vector<sim::TraceRow>& trace, double radius_m) {
  std::vector<gpu::RaycastPrim> prims;
  const std::size_t step = std::max<std::size_t>(1, trace.size() / 200);
  for (std::size_t i = step; i < trace.size(); i += step) {
    const Vec3 a = trace[i - step].hip_m, b = trace[i].hip_m;
    if (finite(a) && finite(b)) prims.push_back(engine::prim_capsule(a, b, radius_m, kOverviewPathRgb, 1.0f, true));
  }
  for (const sim::TraceRow& r : trace)
    if (r.contact && finite(r.vhip_m)) {
      prims.push_back(engine::prim_sphere(r.vhip_m, 2.5 * radius_m, {1.0f, 1.0f, 1.0f}, 1.0f, true));
      break;
    }
  return prims;
}

std::unique_ptr<engine::VulkanContext> own_context(engine::VulkanContext*& vk, const std::string& device) {
  if (vk || is_cpu_device(device)) return nullptr;
  engine::ContextOptions co;
  co.device = device;
  auto c = engine::VulkanContext::create(co);
  if (!c) throw std::runtime_error("Vulkan: " + c.error);
  std::unique_ptr<engine::VulkanContext> own = std::move(*c.value);
  vk = own.get();
  return own;
}

}  // namespace

RunPicture render_overview(const io::Scene& scene, const engine::Volume& vol, const core::SampleField& field,
                           const std::vector<sim::TraceRow>& trace, const std::string& out_png,
                           engine::VulkanContext* vk, const std::string& device, int width, int height) {
  RunPicture out;
  try {
    const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
    const engine::RaycastField rf = engine::make_raycast_field(vol.grid, vol.voxels, iso, field.background);
    PictureRequest req;
    req.width = width;
    req.height = height;
    req.view = overview_view(vol, iso);
    req.prims = path_prims(trace, std::max(0.005 * norm(vol.grid.extent_m()), 0.3 * probe_size_m(vol.grid)));
    const std::unique_ptr<engine::VulkanContext> own = own_context(vk, device);
    const engine::RaycastImage img = render_picture(vk, rf, vol.direction, req, out_png);
    out.gpu_ms = img.gpu_ms;
    const engine::OrbitCamera cam = default_camera(vol);
    out.up = patient_axis(cam.up_phys);
    out.caption = "seen from the " + patient_axis(cam.front_phys) + ", " + out.up + " up";
  } catch (const std::exception& e) {
    out.error = e.what();
  }
  return out;
}

std::string overview_sentence(const RunPicture& pic) {
  if (!pic.error.empty()) return std::string(kOverviewFile) + ": not drawn (" + pic.error + ").";
  return std::string(kOverviewFile) + ": the whole object " + pic.caption +
         " (the volume's direction matrix says where that is), the probe's path in magenta, its first contact white.";
}

}  // namespace isotouch::run
