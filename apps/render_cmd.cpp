#include "render_cmd.h"
#include "vdb_io.h"
#include "stats.h"
#include "bench_cmd.h"

#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csetjmp>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "cli_checks.h"
#include "files.h"
#include "output_file.h"
#include "run_job.h"
#include "shapes.h"
#include "synthetic.h"
#include "volume_io.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace isotouch::app {
using core::cross;
using core::dot;
using core::finite;
using core::norm;
using eval::median;
using io::load_any_volume;
using io::load_scene;
using core::Vec3;
using io::Scene;
namespace fs = std::filesystem;
using core::Vec3;

// ---- isotouch render -----------------------------------------------------------------

namespace {

struct RenderCli {
  std::string up, front;  ///< physical axes; empty: the volume's default (default_camera)
  std::string scene;
  std::string out;
  int width = 640, height = 640;
  engine::OrbitCamera cam;
  std::optional<double> time_s;
  std::string trace;
  std::string clip_axis;
  double clip_at = 0.5;
  bool no_skip = false;
  bool cpu = false;
  bool path = false;
  float step = 0.5f;
};

/// The command's own messages: on stderr when the picture itself goes to standard output.
std::ostream& say(const RenderCli& o) { return o.out == "-" ? std::cerr : std::cout; }

std::string default_scene_path() {
  if (fs::exists("scenes/head.json")) return "scenes/head.json";
  return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "head.json").string();
}

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
std::vector<sim::TraceRow> trace_for(const Scene& scene, const engine::Volume& vol, const RenderCli& o,
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

int cmd_render(const RenderCli& o, const std::string& device) {
  const Scene scene = load_scene(o.scene);
  const engine::Volume vol = load_scene_volume(scene);
  const engine::RaycastField field = scene_raycast_field(scene, vol);
  PictureRequest req;
  req.width = o.width;
  req.height = o.height;
  req.camera = o.cam;
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
    say(o) << "render: wrote " << out << ": " << pic.caption << "\n";
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
  return 0;
}

}  // namespace

Subcommand add_render_command(CLI::App& cli) {
  auto o = std::make_shared<RenderCli>();
  Subcommand s;
  s.app = cli.add_subcommand(
      "render",
      "Ray-cast the scene's isosurface to a PNG (headless, any Vulkan device).\n"
      "The surface is the trilinear field the servo feels, at the scene's isovalue. Camera: an orbit\n"
      "around the volume centre; angles in the volume's physical frame (LPS for medical images):\n"
      "azimuth 0 looks at the face from the front (eye anterior), 90 from the patient's left, -90\n"
      "from the right, 180 from behind; elevation > 0 looks down from above; physical +z is up.\n"
      "With --time T the probe at that time of the scene's run is drawn in: HIP (yellow, seen\n"
      "through the surface), VHIP (green), the virtual plane (translucent cyan disc), the force\n"
      "(red arrow); the scene is run first unless --trace gives its trace.csv.\n"
      "Example: isotouch render scenes/head.json --out head.png --azimuth -90 --time 1.2");
  s.app->add_option("scene", o->scene, "Scene file (default scenes/head.json)");
  s.app->add_option("--out", o->out, "PNG file to write (default <scene name>.png)");
  s.app->add_option("--width", o->width, "Image width [pixels]; width x height at most the device's storage-binding limit / 4 B (lavapipe: 128 MiB, 33554432 pixels)")->capture_default_str()->check(CLI::Range(1, 8192));
  s.app->add_option("--height", o->height, "Image height [pixels]; see --width")->capture_default_str()->check(CLI::Range(1, 8192));
  s.app->add_option("--azimuth", o->cam.azimuth_deg, "Camera azimuth about physical +z [deg]")
      ->capture_default_str()
      ->check(CLI::Range(-3600.0, 3600.0));  // also refuses nan / inf
  s.app->add_option("--elevation", o->cam.elevation_deg, "Camera elevation [deg], in (-90, 90)")
      ->capture_default_str()
      ->check(CLI::Range(-89.9, 89.9));
  s.app->add_option("--zoom", o->cam.zoom, "Zoom: 1 fits the whole volume, 2 is twice as close")
      ->capture_default_str()
      ->check(positive_number());
  s.app->add_option("--distance", o->cam.distance_m, "Eye to volume centre [m] before zoom (0: fit the volume)")
      ->capture_default_str()
      ->check(non_negative_number());
  s.app->add_option("--fov", o->cam.fov_y_deg, "Vertical field of view [deg]")->capture_default_str()->check(CLI::Range(1.0, 120.0));
  s.app->add_option("--up", o->up, "Physical axis shown up: x, -x, y, -y, z, -z (default z; -z for the headsq CT, "
                    "which is stored upside down)");
  s.app->add_option("--front", o->front, "Physical axis the eye is on at azimuth 0 (default -y: anterior)");
  s.app->add_option("--time", o->time_s, "Draw the probe at this time of the scene's run [s]")->check(non_negative_number());
  s.app->add_option("--trace", o->trace, "With --time: the run's trace.csv (default: run the scene now)")
      ->check(CLI::ExistingFile);
  s.app->add_option("--clip", o->clip_axis,
                    "Cut away the half of the volume toward this physical axis: x, -x, y, -y, z, -z "
                    "(e.g. -y removes the anterior half)");
  s.app->add_option("--clip-at", o->clip_at, "Where the clip plane lies along that axis, 0..1 of the volume")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  s.app->add_option("--step", o->step, "March step along the ray [voxels]; at most 0.9 (the hit is refined within one step from the 3x3x3 voxels around it)")->capture_default_str()->check(CLI::Range(0.02, 0.9));  // ISOTOUCH_RAYCAST_MAX_STEP (make_params compares in float)
  s.app->add_flag("--path", o->path,
                  "Draw the run report's picture instead: the surface around the contact, the HIP's path, the "
                  "contact points coloured by force (the scene is run unless --trace is given)");
  s.app->add_flag("--no-skip", o->no_skip, "Turn empty-space skipping off (same picture, slower)");
  s.app->add_flag("--cpu", o->cpu, "Use the CPU reference ray caster instead of Vulkan");
  s.run = [o](const std::string& device) {
    RenderCli c = *o;
    if (c.scene.empty()) c.scene = default_scene_path();
    if (!c.trace.empty() && !c.time_s && !c.path) throw std::runtime_error("render: --trace needs --time or --path");
    return cmd_render(c, device);
  };
  return s;
}

// ---- isotouch bench render -----------------------------------------------------------

namespace {

struct BenchRow {
  std::string name;
  std::array<int, 3> dims{};
  double ms_skip = 0, ms_noskip = 0;  ///< medians
  double march_skip = 0, march_noskip = 0, shade_skip = 0;  ///< medians of the pass times
  double wall_skip = 0, wall_noskip = 0;  ///< medians, submit to fence (with readback)
  std::size_t pixels_differ = 0;      ///< depth differs between skip on and off
  std::size_t hits = 0;
  bool timestamps = true;
  double build_ms = 0;                ///< engine::cell_distances on the host, median
};


BenchRow bench_scene(engine::VulkanContext& vk, const std::string& scene_path, int size, int frames) {
  const Scene scene = load_scene(scene_path);
  const engine::Volume vol = load_scene_volume(scene);
  const engine::RaycastField field = scene_raycast_field(scene, vol);
  auto rc = engine::RayCaster::create(vk, field);
  if (!rc) throw std::runtime_error(rc.error);
  const engine::CameraView view = engine::orbit_view(field.grid, vol.direction, default_camera(vol));
  BenchRow row;
  row.name = scene.name;
  row.dims = vol.grid.dims;
  {  // The skipping structure is rebuilt from the values whenever they change: its host cost.
    std::vector<double> ms;
    for (int i = 0; i < 5; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      const auto d = engine::cell_distances(field.grid, field.values, field.iso, field.background);
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      if (d.size() != field.cell_dist.size()) throw std::runtime_error("bench render: cell distances changed size");
    }
    row.build_ms = median(ms);
  }
  // Skipping on and off alternate frame by frame (a shared machine's speed drifts: both
  // medians see the same drift). Frame 0 of each: warm-up.
  engine::RaycastImage last[2];
  std::vector<double> ms[2], march[2], shade, wall[2];
  for (int f = 0; f <= frames; ++f)
    for (int skip = 1; skip >= 0; --skip) {
      engine::RaycastStyle st;
      st.skip_empty = skip == 1;
      engine::RaycastImage img = (*rc.value)->render(view, st, size, size);
      if (f > 0) {
        ms[skip].push_back(img.gpu_ms >= 0 ? img.gpu_ms : img.submit_wall_ms);
        march[skip].push_back(img.march_ms);
        wall[skip].push_back(img.submit_wall_ms);
        if (skip) shade.push_back(img.shade_ms);
      }
      row.timestamps = row.timestamps && img.gpu_ms >= 0;
      last[skip] = std::move(img);
    }
  row.ms_skip = median(ms[1]);
  row.ms_noskip = median(ms[0]);
  row.march_skip = median(march[1]);
  row.march_noskip = median(march[0]);
  row.shade_skip = median(shade);
  row.wall_skip = median(wall[1]);
  row.wall_noskip = median(wall[0]);
  for (std::size_t i = 0; i < last[0].depth.size(); ++i) {
    row.pixels_differ += last[0].depth[i] != last[1].depth[i] || last[0].rgba[i] != last[1].rgba[i];
    row.hits += last[1].depth[i] >= 0;
  }
  return row;
}

int cmd_bench_render(int size, int frames, const std::string& device) {
  engine::ContextOptions co;
  co.device = device;
  auto c = engine::VulkanContext::create(co);
  if (!c) throw std::runtime_error("Vulkan: " + c.error);
  engine::VulkanContext& vk = **c.value;
  const bool cpu_device = vk.info().type == "cpu";
  std::cout << "isotouch bench render: " << size << " x " << size << " frames, default camera (orbit, azimuth 0, "
            << "elevation 10 deg, whole volume), step 0.5 voxel, median of " << frames
            << " frames after one warm-up, skipping on and off alternating\n"
            << "device: " << vk.info().name << " (" << vk.info().type << ", " << vk.info().driver << ")\n\n"
            << "load average before: " << load_average() << "\n\n"
            << "| scene | voxels | surface pixels | ms/frame skipping | ms/frame no skipping | speed-up | images equal "
               "| march pass skipping / no skipping [ms] | shade pass [ms] | submit to fence skipping / no skipping [ms] "
               "| cell distances built [ms, host] |\n"
            << "|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::vector<BenchRow> rows;
  for (const char* s : {"head.json", "chest.json"}) {
    fs::path p = fs::path("scenes") / s;
    if (!fs::exists(p)) p = fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / s;
    rows.push_back(bench_scene(vk, p.string(), size, frames));
    const BenchRow& r = rows.back();
    std::cout << std::fixed << std::setprecision(1) << "| " << r.name << " | " << r.dims[0] << "x" << r.dims[1] << "x"
              << r.dims[2] << " | " << r.hits << " | " << r.ms_skip << " | " << r.ms_noskip << " | "
              << std::setprecision(2) << r.ms_noskip / r.ms_skip << "x | "
              << (r.pixels_differ == 0 ? "yes" : "NO (" + std::to_string(r.pixels_differ) + " pixels)") << " | "
              << std::setprecision(1) << r.march_skip << " / " << r.march_noskip << " | " << r.shade_skip << " | "
              << r.wall_skip << " / " << r.wall_noskip << " | " << r.build_ms << " |\n";
  }
  const BenchRow& head = rows[0];
  const double speedup = head.ms_noskip / head.ms_skip;
  std::cout << "\nload average after: " << load_average() << "\n(ms: " << (head.timestamps ? "GPU timestamps around the passes" : "submit-to-fence wall time")
            << "; the march pass runs the pixels the volume's box projects to (skipping: the box of the active cells), the shade pass only the hit pixels; "
               "the machine may be shared: figures vary by tens of %)\n"
            << std::setprecision(2) << "verdict: head skipping speed-up " << speedup << "x (needs >= 5x): "
            << (speedup >= 5 ? "PASS" : "FAIL") << "\n"
            << std::setprecision(1) << "verdict: head " << head.ms_skip << " ms per " << size << "x" << size
            << " frame with skipping (needs <= 100 ms on lavapipe): "
            << (!cpu_device ? std::string("n/a (not a CPU device)") : head.ms_skip <= 100 ? "PASS" : "FAIL") << "\n";
  bool equal = true;
  for (const auto& r : rows) equal = equal && r.pixels_differ == 0;
  std::cout << "verdict: skipping on and off give the same images: " << (equal ? "PASS" : "FAIL") << "\n";
  return 0;
}

}  // namespace

Subcommand add_bench_render_command(CLI::App& bench) {
  auto size = std::make_shared<int>(512);
  auto frames = std::make_shared<int>(9);
  Subcommand s;
  s.app = bench.add_subcommand("render",
                               "ms per frame of the ray caster on the head and chest CTs, with and without "
                               "empty-space skipping (GPU timestamps)");
  s.app->add_option("--size", *size, "Frame width and height [pixels]")->capture_default_str()->check(CLI::Range(16, 4096));
  s.app->add_option("--frames", *frames, "Timed frames per configuration (median)")->capture_default_str()->check(CLI::Range(1, 1000));
  s.run = [size, frames](const std::string& device) { return cmd_bench_render(*size, *frames, device); };
  return s;
}

}  // namespace isotouch::app
