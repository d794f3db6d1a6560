#include "isotouch/run/picture.h"

#include <png.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include "isotouch/run/names.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/eval/shapes.h"

namespace isotouch::run {
using core::cross;
using core::dot;
using core::finite;
using core::norm;
namespace fs = std::filesystem;

// ---- PNG ---------------------------------------------------------------------------------

namespace {
/// libpng with setjmp error handling; only plain data lives in this frame.
/// @return "" or libpng's message.
const char* png_write_rows(std::FILE* f, int width, int height, const unsigned char* rgb) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (!png) return "png_create_write_struct failed";
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return "png_create_info_struct failed";
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return "libpng error while writing (libpng printed the reason)";
  }
  png_init_io(png, f);
  png_set_compression_level(png, 9);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y) png_write_row(png, rgb + std::size_t(y) * std::size_t(width) * 3);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return "";
}
}  // namespace

void write_png(const std::string& path, int width, int height, const std::vector<std::uint32_t>& rgba) {
  if (width < 1 || height < 1 || rgba.size() != std::size_t(width) * std::size_t(height))
    throw std::runtime_error(path + ": image of " + std::to_string(rgba.size()) + " pixels is not " +
                             std::to_string(width) + " x " + std::to_string(height));
  std::vector<unsigned char> rgb(rgba.size() * 3);
  for (std::size_t i = 0; i < rgba.size(); ++i)
    for (int c = 0; c < 3; ++c) rgb[3 * i + std::size_t(c)] = static_cast<unsigned char>((rgba[i] >> (8 * c)) & 0xffu);
  const fs::path parent = fs::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty() && path != "-") fs::create_directories(parent, ec);
  try {
    io::write_output(path, [&](const std::string& file) {
      std::FILE* f = std::fopen(file.c_str(), "wb");
      if (!f) throw std::runtime_error(path + ": cannot write (" + file + "): " + std::strerror(errno));
      const std::string err = png_write_rows(f, width, height, rgb.data());
      const bool closed = std::fclose(f) == 0;
      if (!err.empty() || !closed)
        throw std::runtime_error(path + ": " + (err.empty() ? std::string("close failed: ") + std::strerror(errno) : err));
    });
  } catch (const io::OutputError& e) {
    throw std::runtime_error(e.what());
  }
}

// ---- volumes, fields, pictures ---------------------------------------------------------

engine::Volume load_scene_volume(const Scene& scene) {
  if (!scene.volume_path.empty()) return load_any_volume(scene.volume_path);
  if (scene.synthetic.kind == "sphere")
    return engine::make_sphere(scene.synthetic.dims, scene.synthetic.spacing_m, scene.synthetic.radius_vox);
  return std::move(eval::make_synthetic_scene(scene.synthetic.kind).volume);
}

engine::RaycastField scene_raycast_field(const Scene& scene, const engine::Volume& vol) {
  const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
  if (vol.finite_voxels == 0) throw std::runtime_error(vol.path + ": no finite voxels: there is no isosurface");
  const float bg = float(iso.outside_value(vol.min_value, vol.max_value));
  return engine::make_raycast_field(vol.grid, vol.voxels, iso, bg);
}

engine::RaycastImage render_picture(engine::VulkanContext* vk, const engine::RaycastField& field,
                                    const std::array<double, 9>& direction, const PictureRequest& req,
                                    const std::string& out_png) {
  const engine::CameraView view = req.view ? *req.view : engine::orbit_view(field.grid, direction, req.camera);
  engine::RaycastImage img;
  if (req.cpu || vk == nullptr) {
    img = engine::render_cpu(field, view, req.style, req.width, req.height, req.prims);
  } else {
    auto rc = engine::RayCaster::create(*vk, field);
    if (!rc) throw std::runtime_error(rc.error);
    img = (*rc.value)->render(view, req.style, req.width, req.height, req.prims);
  }
  if (!out_png.empty()) write_png(out_png, img.width, img.height, img.rgba);
  return img;
}

engine::OrbitCamera default_camera(const engine::Volume&) {
  // The orbit camera's angles are physical (the direction matrix turns them into the grid
  // frame): superior up and the eye anterior for every volume, whatever its file is called.
  return engine::OrbitCamera{};
}

std::string patient_axis(const Vec3& phys) {
  static const char* kNames[3][2] = {{"left", "right"}, {"posterior", "anterior"}, {"superior", "inferior"}};
  const double c[3] = {phys.x, phys.y, phys.z};
  for (int a = 0; a < 3; ++a)
    if (std::abs(c[a]) > 0.999 * norm(phys)) return kNames[a][c[a] > 0 ? 0 : 1];
  std::ostringstream s;
  s << std::setprecision(3) << "(" << phys.x << ", " << phys.y << ", " << phys.z << ") LPS";
  return s.str();
}

void roll_camera(engine::OrbitCamera& cam, int quarter_turns) {
  const int n = ((quarter_turns % 4) + 4) % 4;
  for (int i = 0; i < n; ++i) cam.up_phys = cross(cam.front_phys, cam.up_phys);
}

double probe_size_m(const core::Grid& g) {
  const double s = std::max({g.spacing_m.x, g.spacing_m.y, g.spacing_m.z});
  return 0.6 * std::max(s, 1e-3);
}

std::vector<gpu::RaycastPrim> probe_prims(const sim::TraceRow& r, double force_limit_n, double u) {
  std::vector<gpu::RaycastPrim> p;
  p.push_back(engine::prim_sphere(r.hip_m, 1.2 * u, {0.95f, 0.80f, 0.10f}, 1.0f, true));
  p.push_back(engine::prim_sphere(r.vhip_m, 1.0 * u, {0.15f, 0.80f, 0.25f}));
  const double f = norm(r.force_n);
  if (f > 1e-9 && std::isfinite(f)) {
    const Vec3 n = r.force_n / f;
    p.push_back(engine::prim_disc(r.vhip_m, n, 6.0 * u, {0.20f, 0.75f, 0.95f}, 0.45f));
    const double len = std::min(f / std::max(force_limit_n, 1e-9), 1.5) * 12.0 * u;
    engine::add_arrow(p, r.vhip_m, r.vhip_m + n * len, 0.35 * u, {0.90f, 0.15f, 0.10f});
  }
  return p;
}

namespace {

/// Blue -> cyan -> green -> yellow -> red for s in [0, 1].
std::array<float, 3> force_colour(double s) {
  s = std::clamp(s, 0.0, 1.0);
  const double r = std::clamp(2.0 * s - 0.5, 0.0, 1.0) * 1.0;
  const double g = s < 0.75 ? std::clamp(2.0 * s, 0.0, 1.0) : 1.0 - (s - 0.75) * 4.0;
  const double b = std::clamp(1.0 - 2.5 * s, 0.0, 1.0);
  return {float(r), float(g), float(b)};
}

/// The default camera's physical up, or the front axis if up is along `view_dir` (grid-world):
/// that physical axis and its grid-world direction.
std::pair<Vec3, Vec3> picture_up(const engine::Volume& vol, const Vec3& view_dir) {
  const auto& D = vol.direction;
  const engine::OrbitCamera cam = default_camera(vol);
  for (Vec3 p : {cam.up_phys, -cam.front_phys}) {
    const Vec3 g{D[0] * p.x + D[3] * p.y + D[6] * p.z, D[1] * p.x + D[4] * p.y + D[7] * p.z,
                 D[2] * p.x + D[5] * p.y + D[8] * p.z};
    if (norm(cross(g, view_dir)) > 0.3) return {p, g};
  }
  return {vol.direction_apply({1, 0, 0}), {1, 0, 0}};
}

}  // namespace

RunPicture render_run_picture(const Scene& scene, const engine::Volume& vol, const core::SampleField& field,
                              const std::vector<sim::TraceRow>& trace, const std::string& out_png,
                              engine::VulkanContext* vk, const std::string& device, int width, int height) {
  RunPicture out;
  try {
    if (trace.empty()) throw std::runtime_error("no ticks in the trace");
    const core::Isosurface iso{scene.hri.tau, scene.hri.inside};
    engine::RaycastField rf = engine::make_raycast_field(vol.grid, vol.voxels, iso, field.background);
    const double u = probe_size_m(vol.grid);
    // Contact points, their force range, the mean force direction, the tick of max |F|.
    double fmax = 0;
    std::size_t imax = 0, contacts = 0;
    Vec3 centroid, fsum;
    for (std::size_t i = 0; i < trace.size(); ++i) {
      const sim::TraceRow& r = trace[i];
      if (!r.contact || !finite(r.vhip_m)) continue;
      ++contacts;
      centroid += r.vhip_m;
      fsum += r.force_n;
      if (norm(r.force_n) > fmax) {
        fmax = norm(r.force_n);
        imax = i;
      }
    }
    std::vector<gpu::RaycastPrim> prims;
    const std::size_t room = ISOTOUCH_RAYCAST_MAX_PRIMS - 16;
    // The HIP's path: at most 150 segments, thin, seen through the surface.
    const std::size_t seg_step = std::max<std::size_t>(1, trace.size() / 150);
    for (std::size_t i = seg_step; i < trace.size(); i += seg_step)
      if (finite(trace[i - seg_step].hip_m) && finite(trace[i].hip_m) && norm(trace[i].hip_m - trace[i - seg_step].hip_m) > 1e-9)
        prims.push_back(engine::prim_capsule(trace[i - seg_step].hip_m, trace[i].hip_m, 0.22 * u, {0.85f, 0.85f, 0.85f},
                                             1.0f, true));
    // Contact points: at most ~400, coloured by |F| / max |F|.
    const std::size_t pt_step = std::max<std::size_t>(1, contacts / 400);
    std::size_t k = 0;
    for (const sim::TraceRow& r : trace) {
      if (!r.contact || !finite(r.vhip_m)) continue;
      if (k++ % pt_step != 0 || prims.size() >= room) continue;
      prims.push_back(engine::prim_sphere(r.vhip_m, 0.45 * u, force_colour(fmax > 0 ? norm(r.force_n) / fmax : 0)));
    }
    Vec3 target, view_dir;
    if (contacts > 0) {
      for (const auto& q : probe_prims(trace[imax], scene.hri.force_limit_n, u)) prims.push_back(q);
      target = centroid / double(contacts);
      view_dir = norm(fsum) > 0 ? fsum / -norm(fsum) : core::normalized_or(scene.script.ray_direction, Vec3{1, 0, 0});
    } else {
      for (const auto& r : trace) target += r.hip_m;
      target = target / double(trace.size());
      view_dir = core::normalized_or(scene.script.ray_direction, Vec3{1, 0, 0});
    }
    double extent = 0;
    for (const auto& r : trace)
      if (finite(r.hip_m)) extent = std::max(extent, norm(r.hip_m - target));
    const double fov = 35;
    const double half_width = std::max(1.4 * extent, 0.02);
    const double dist = half_width / std::tan(0.5 * fov * 3.14159265358979 / 180);
    PictureRequest req;
    req.width = width;
    req.height = height;
    const auto [up_phys, up_grid] = picture_up(vol, view_dir);
    req.view = engine::look_at(target - view_dir * dist, target, up_grid, fov);
    // With a reflection D (det < 0) the grid frame's right is the physical left (orbit_view
    // does the same): the picture shows the volume, not its mirror image.
    const auto& D = vol.direction;
    if (D[0] * (D[4] * D[8] - D[5] * D[7]) - D[1] * (D[3] * D[8] - D[5] * D[6]) + D[2] * (D[3] * D[7] - D[4] * D[6]) < 0)
      req.view->right = req.view->right * -1.0;
    out.up = patient_axis(up_phys);
    req.prims = std::move(prims);
    std::unique_ptr<engine::VulkanContext> own;
    if (!vk && !is_cpu_device(device)) {
      engine::ContextOptions co;
      co.device = device;
      auto c = engine::VulkanContext::create(co);
      if (!c) throw std::runtime_error("Vulkan: " + c.error);
      own = std::move(*c.value);
      vk = own.get();
    }
    const engine::RaycastImage img = render_picture(vk, rf, vol.direction, req, out_png);
    out.gpu_ms = img.gpu_ms;
    std::ostringstream c;
    c << std::setprecision(3) << "isosurface " << scene.hri.tau << " (" << core::to_string(scene.hri.inside)
      << "); grey: the HIP's path (seen through the surface); dots: " << contacts
      << " contact ticks (VHIP, every " << pt_step << ") coloured by |F| from 0 N (blue) through green and yellow to "
      << fmax << " N (red); probe at t = " << trace[imax].t_s
      << " s (largest force): HIP yellow, VHIP green, virtual plane cyan, force red arrow";
    out.caption = c.str();
  } catch (const std::exception& e) {
    out.error = e.what();
  }
  return out;
}

}  // namespace isotouch::run
