// render_job.cpp - what `isotouch render` runs; see render_job.h.
#include "isotouch/run/render_job.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "isotouch/run/names.h"
#include "isotouch/run/object_box.h"
#include "isotouch/run/picture.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/trace_csv.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::run {
using core::Vec3;
using io::load_scene;
using io::Scene;
namespace fs = std::filesystem;

namespace {

/// The command's own messages: on stderr when the picture itself goes to standard output.
std::ostream& say(const RenderOptions& o) { return o.out == "-" ? std::cerr : std::cout; }

/// A clip plane perpendicular to a physical axis ("x", "-y", ...; L, P, S positive) at
/// fraction `at` of the volume's extent along it; removes the side the axis points to.
engine::ClipPlane clip_plane(const engine::Volume& vol, const std::string& axis, double at) {
  static const std::pair<const char*, Vec3> axes[] = {{"x", {1, 0, 0}},  {"-x", {-1, 0, 0}}, {"y", {0, 1, 0}},
                                                      {"-y", {0, -1, 0}}, {"z", {0, 0, 1}},  {"-z", {0, 0, -1}}};
  for (const auto& [name, phys] : axes) {
    if (axis != name) continue;
    const auto& D = vol.direction;
    const Vec3 n{D[0] * phys.x + D[3] * phys.y + D[6] * phys.z, D[1] * phys.x + D[4] * phys.y + D[7] * phys.z,
                 D[2] * phys.x + D[5] * phys.y + D[8] * phys.z};
    // Extent of the box of voxel centres along n (grid-world).
    const Vec3 lo = vol.grid.origin_m, hi = vol.grid.origin_m + vol.grid.extent_m();
    double a = 1e300, b = -1e300;
    for (int c = 0; c < 8; ++c) {
      const Vec3 p{c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y, c & 4 ? hi.z : lo.z};
      a = std::min(a, dot(n, p));
      b = std::max(b, dot(n, p));
    }
    // at = 0: the plane at the far end (everything removed); 1: the near end... keep it
    // simple: the plane at a + at (b - a) along n.
    const double s = a + at * (b - a);
    return {n * s, n};
  }
  throw std::runtime_error("render: --clip must be one of x, -x, y, -y, z, -z (physical axes), got '" + axis + "'");
}

/// A physical axis by name: x, -x, y, -y, z, -z (LPS: +x left, +y posterior, +z superior).
Vec3 parse_axis(const std::string& name, const char* option) {
  static const std::pair<const char*, Vec3> axes[] = {{"x", {1, 0, 0}},  {"-x", {-1, 0, 0}}, {"y", {0, 1, 0}},
                                                      {"-y", {0, -1, 0}}, {"z", {0, 0, 1}},  {"-z", {0, 0, -1}}};
  for (const auto& [n, v] : axes)
    if (name == n) return v;
  throw std::runtime_error(std::string("render: ") + option + " must be one of x, -x, y, -y, z, -z, got '" + name + "'");
}

sim::TraceRow row_at(const std::vector<sim::TraceRow>& rows, double t) {
  auto it = std::lower_bound(rows.begin(), rows.end(), t, [](const sim::TraceRow& r, double v) { return r.t_s < v; });
  if (it == rows.end()) --it;
  return *it;
}

/// The trace to draw at --time: --trace FILE, else the scene run now into a temporary folder.
std::vector<sim::TraceRow> trace_for(const Scene& scene, const engine::Volume& vol, const RenderOptions& o,
                                       const std::string& device) {
  if (!o.trace.empty()) return read_trace_csv(o.trace, vol);
  const fs::path tmp = fs::temp_directory_path() / ("isotouch-render-" + std::to_string(::getpid()));
  RunOptions ro;
  ro.out_dir = tmp.string();
  ro.device = device;
  ro.progress = false;
  Scene s = scene;
  s.draw_plots = false;
  s.write_trace = true;
  std::ostringstream log;
  say(o) << "render: running the scene to get the probe's trace ...\n";
  try {
    run_scene(s, ro, log);
    auto rows = read_trace_csv((tmp / "trace.csv").string(), vol);
    fs::remove_all(tmp);
    return rows;
  } catch (...) {
    std::error_code ec;
    fs::remove_all(tmp, ec);
    throw;
  }
}

}  // namespace

int run_render(const RenderOptions& o, const std::string& device) {
  const Scene scene = load_scene(o.scene);
  const engine::Volume vol = load_scene_volume(scene);
  const engine::RaycastField field = scene_raycast_field(scene, vol);
  PictureRequest req;
  req.width = o.width;
  req.height = o.height;
  // The object framed, not the scan around it: the overview's framing (run::frame_object).
  req.camera = o.frame_scan ? o.cam : frame_object(o.cam, vol, core::Isosurface{scene.hri.tau, scene.hri.inside});
  const engine::OrbitCamera def = default_camera(vol);
  req.camera.up_phys = o.up.empty() ? def.up_phys : parse_axis(o.up, "--up");
  req.camera.front_phys = o.front.empty() ? def.front_phys : parse_axis(o.front, "--front");
  req.cpu = o.cpu;
  req.style.skip_empty = !o.no_skip;
  req.style.step_vox = o.step;
  if (!o.clip_axis.empty()) req.style.clip = clip_plane(vol, o.clip_axis, o.clip_at);
  if (o.path) {
    const auto rows = trace_for(scene, vol, o, device);
    core::SampleField sf;
    sf.background = field.background;
    const std::string out = o.out.empty() ? scene.name + "_path.png" : o.out;
    const RunPicture pic = render_run_picture(scene, vol, sf, rows, out, nullptr, device, o.width, o.height);
    if (!pic.error.empty()) throw std::runtime_error("render --path: " + pic.error);
    say(o) << "render: wrote " << out << ": " << pic.caption << "\n" << "render: up: " << pic.up << "\n";
    return 0;
  }
  std::string probe_note;
  if (o.time_s) {
    const auto rows = trace_for(scene, vol, o, device);
    const sim::TraceRow r = row_at(rows, *o.time_s);
    req.prims = probe_prims(r, scene.hri.force_limit_n, probe_size_m(vol.grid));
    std::ostringstream s;
    s << std::setprecision(4) << "probe at t = " << r.t_s << " s: " << (r.contact ? "contact" : "no contact")
      << ", |F| = " << norm(r.force_n) << " N";
    probe_note = s.str();
  }
  std::unique_ptr<engine::VulkanContext> vk;
  if (!o.cpu) {
    engine::ContextOptions co;
    co.device = device;
    auto c = engine::VulkanContext::create(co);
    if (!c) throw std::runtime_error("Vulkan: " + c.error);
    vk = std::move(*c.value);
  }
  if (vk) {  // the image is one storage buffer of 4 B per pixel: the device's binding limit bounds it
    const std::uint64_t limit = vk->max_binding_bytes(), need = 4ull * std::uint64_t(req.width) * std::uint64_t(req.height);
    if (need > limit) {
      const auto side = std::uint64_t(std::sqrt(double(limit / 4)));
      throw std::runtime_error("--width " + std::to_string(req.width) + " x --height " + std::to_string(req.height) + " = " +
                               std::to_string(need / 4) + " pixels need " + std::to_string(need >> 20) +
                               " MiB per image buffer; the Vulkan device " + std::string(vk->properties().deviceName) + " binds at most " +
                               std::to_string(limit >> 20) + " MiB: at most " + std::to_string(limit / 4) +
                               " pixels (e.g. " + std::to_string(side) + " x " + std::to_string(side) + "), or --cpu");
    }
  }
  const std::string out = o.out.empty() ? scene.name + ".png" : o.out;
  const engine::RaycastImage img = render_picture(vk.get(), field, vol.direction, req, out);
  std::size_t hits = 0;
  for (float d : img.depth) hits += d >= 0;
  say(o) << "render: wrote " << out << " (" << img.width << " x " << img.height << ", "
            << (vk ? vk->info().name : std::string("CPU reference")) << ", "
            << std::setprecision(3) << (img.gpu_ms >= 0 ? img.gpu_ms : img.submit_wall_ms) << " ms"
            << (img.gpu_ms >= 0 ? " GPU" : " wall") << ", " << hits << " surface pixels"
            << (probe_note.empty() ? "" : "; " + probe_note) << ")\n";
  say(o) << "render: up: " << patient_axis(req.camera.up_phys) << ", eye at azimuth 0: "
         << patient_axis(req.camera.front_phys) << "\n";
  return 0;
}

}  // namespace isotouch::run
