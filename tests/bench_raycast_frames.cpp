// bench_raycast_frames - whole frames of the ray caster (what isotouch-sculpt draws after an
// orbit, pan or zoom) on the head and chest CTs, in four configurations measured side by
// side in one run: the voxels read 4 per texel (quads, binding 12) with tile starts (the
// cone-stepping pass, RaycastStyle::tile_starts), quads without tile starts, 1 voxel per
// texel with tile starts, and the values binding 4 voxels per texel (as a volume past one
// binding of single floats reads them; forced here by a limit one texel below the voxels)
// with tile starts. The same cameras go to every configuration in turn (the order
// rotating per frame); GPU timestamps per pass and the submit-to-fence wall time (median and
// p95 over the frames); and whether every frame's picture and depth are bit-identical across
// the configurations (tile starts and quads only change how fast the same picture is drawn).
// Also the process's CPU time per frame (lavapipe's threads included: on a CPU device the
// work a frame costs, less sensitive than wall time to what else runs on the machine).
// Usage: bench_raycast_frames [WIDTH HEIGHT FRAMES [VOLUME TAU]] (default 1024 768 24; a
// VOLUME, at isovalue TAU with inside above, instead of the head and chest scenes)
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <sys/resource.h>

#include "isotouch/engine/raycast.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/run/picture.h"
#include "isotouch/io/scene.h"
#include "isotouch/engine/vk_context.h"

using namespace isotouch;

namespace {
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? -1 : v[v.size() / 2];
}
double p95(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? -1 : v[std::min(v.size() - 1, std::size_t(0.95 * double(v.size())))];
}
std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

/// One configuration's per-frame figures [ms].
struct Series {
  std::vector<double> tiles, march, shade, total, wall, cpu;
};

/// The process's user + system CPU time [ms].
double cpu_ms() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) * 1e3 + double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-3;
}

/// How the tile starts did in one frame: the pixels in tiles left out, and the mean distance
/// [voxels along the ray] from a hit pixel's tile start to its hit.
struct TileFigures {
  double left_out = 0, ahead_vox = 0;
};
TileFigures tile_figures(const engine::RaycastImage& img, const std::vector<float>& starts, const core::Grid& grid,
                         const engine::CameraView& view) {
  const int T = int(ISOTOUCH_RAYCAST_TILE), tiles_x = (img.width + T - 1) / T;
  TileFigures out;
  long hit = 0;
  for (int py = 0; py < img.height; ++py)
    for (int px = 0; px < img.width; ++px) {
      const float start = starts[std::size_t(py / T) * std::size_t(tiles_x) + std::size_t(px / T)];
      const float depth = img.depth[std::size_t(py) * std::size_t(img.width) + std::size_t(px)];
      out.left_out += start == std::numeric_limits<float>::infinity();
      if (depth < 0) continue;
      ++hit;
      out.ahead_vox += (double(depth) - double(start)) *
                       engine::voxels_per_metre(grid, engine::pixel_direction(view, img.width, img.height, px, py));
    }
  out.ahead_vox /= double(std::max(hit, 1L));
  return out;
}

bool same_picture(const engine::RaycastImage& a, const engine::RaycastImage& b) {
  return a.rgba == b.rgba && std::memcmp(a.depth.data(), b.depth.data(), a.depth.size() * 4) == 0;
}

/// One volume measured: its name, voxels and the field drawn.
struct Case {
  std::string name;
  engine::Volume vol;
  engine::RaycastField field;
};
Case scene_case(const char* file) {
  std::filesystem::path p = std::filesystem::path("scenes") / file;
  if (!std::filesystem::exists(p)) p = std::filesystem::path(ISOTOUCH_SOURCE_DIR) / "scenes" / file;
  const io::Scene scene = io::load_scene(p.string());
  Case c{scene.name, run::load_scene_volume(scene), {}};
  c.field = run::scene_raycast_field(scene, c.vol);
  return c;
}
Case volume_case(const std::string& path, double tau) {
  Case c{std::filesystem::path(path).filename().string(), io::load_volume(path), {}};
  const core::Isosurface iso{tau, core::InsideIs::kAbove};
  c.field = engine::make_raycast_field(c.vol.grid, c.vol.voxels, iso,
                                       float(iso.outside_value(c.vol.min_value, c.vol.max_value)));
  return c;
}
}  // namespace

int main(int argc, char** argv) {
  const int width = argc > 2 ? std::atoi(argv[1]) : 1024, height = argc > 2 ? std::atoi(argv[2]) : 768;
  const int frames = argc > 3 ? std::atoi(argv[3]) : 24;
  if (width < 1 || height < 1 || frames < 1) {
    std::fprintf(stderr, "usage: bench_raycast_frames [WIDTH HEIGHT FRAMES]\n");
    return 1;
  }
  auto c = engine::VulkanContext::create(engine::ContextOptions{});
  if (!c) {
    std::fprintf(stderr, "bench_raycast_frames: Vulkan: %s\n", c.error.c_str());
    return 1;
  }
  engine::VulkanContext& vk = **c.value;
  std::printf("bench_raycast_frames: %d x %d, %d frames per scene (orbit 3 deg and zoom 1.02 per frame from the default "
              "camera, as the sculpt bench's camera moves), %s, load average %s\n\n",
              width, height, frames, vk.info().name.c_str(), load_average().c_str());
  std::printf("| scene | configuration | tiles [ms] | march incl. tiles median / p95 [ms] | shade median / p95 [ms] | "
              "march + shade median / p95 [ms] | submit to fence median / p95 [ms] | CPU time median [ms] | hit pixels (median) |\n"
              "|---|---|---|---|---|---|---|---|---|\n");
  bool all_equal = true;
  const int n_cases = argc > 5 ? 1 : 2;
  for (int ci = 0; ci < n_cases; ++ci) {
    Case cs = argc > 5 ? volume_case(argv[4], std::atof(argv[5])) : scene_case(ci == 0 ? "head.json" : "chest.json");
    const engine::Volume& vol = cs.vol;
    const engine::RaycastField& field = cs.field;
    auto q = engine::RayCaster::create(vk, field, true), s = engine::RayCaster::create(vk, field, false);
    auto v4 = engine::RayCaster::create(vk, field, false, field.values.size() - 1);
    if (!q || !s || !v4) {
      std::fprintf(stderr, "bench_raycast_frames: %s\n", (!q ? q.error : !s ? s.error : v4.error).c_str());
      return 1;
    }
    struct Config {
      std::string name;
      engine::RayCaster* caster;
      bool tiles;
    };
    auto per_texel = [](const engine::RayCaster& r) {
      return std::string(r.quads() ? "quads" : r.four_voxels_per_texel() ? "4 per texel" : "1 per texel");
    };
    const std::string quads = per_texel(**q.value);
    constexpr int K = 4;
    const Config cfg[K] = {{quads + ", tile starts", q.value->get(), true},
                           {quads + ", no tile starts", q.value->get(), false},
                           {per_texel(**s.value) + ", tile starts", s.value->get(), true},
                           {per_texel(**v4.value) + " (values binding forced), tile starts", v4.value->get(), true}};
    Series ser[K];
    std::vector<double> hits, left_out, ahead;
    long differ = 0;
    engine::OrbitCamera cam = run::default_camera(vol);
    for (int f = 0; f <= frames; ++f) {  // frame 0: warm-up
      cam.azimuth_deg += 3;
      cam.zoom *= 1.02;
      const engine::CameraView view = engine::orbit_view(vol.grid, vol.direction, cam);
      engine::RaycastImage img[K];
      double cpu[K] = {0, 0, 0, 0};
      for (int k = 0; k < K; ++k) {
        const int i = (f + k) % K;  // rotate which goes first
        engine::RaycastStyle style;
        style.tile_starts = cfg[i].tiles;
        const double c0 = cpu_ms();
        img[i] = cfg[i].caster->render(view, style, width, height);
        cpu[i] = cpu_ms() - c0;
        if (i == 0 && f > 0) {
          const TileFigures t = tile_figures(img[0], cfg[0].caster->last_tile_starts(), vol.grid, view);
          left_out.push_back(t.left_out);
          ahead.push_back(t.ahead_vox);
        }
      }
      if (f == 0) continue;
      for (int i = 0; i < K; ++i) {
        ser[i].tiles.push_back(img[i].tiles_ms);
        ser[i].march.push_back(img[i].march_ms);
        ser[i].shade.push_back(img[i].shade_ms);
        ser[i].total.push_back(img[i].march_ms + img[i].shade_ms);
        ser[i].wall.push_back(img[i].submit_wall_ms);
        ser[i].cpu.push_back(cpu[i]);
      }
      hits.push_back(double(std::count_if(img[0].depth.begin(), img[0].depth.end(), [](float t) { return t >= 0; })));
      if (!same_picture(img[0], img[1]) || !same_picture(img[0], img[2]) || !same_picture(img[0], img[3])) ++differ;
    }
    all_equal = all_equal && differ == 0;
    std::printf("| %s | tile starts: pixels in tiles left out (median) %.0f of %d; a hit's tile start lies %.2f voxels "
                "before the hit (median of the frames' means) | | | | | | | |\n",
                cs.name.c_str(), median(left_out), width * height, median(ahead));
    for (int i = 0; i < K; ++i)
      std::printf("| %s | %s | %.1f | %.1f / %.1f | %.1f / %.1f | %.1f / %.1f | %.1f / %.1f | %.1f | %.0f |\n",
                  cs.name.c_str(), cfg[i].name.c_str(), median(ser[i].tiles), median(ser[i].march), p95(ser[i].march),
                  median(ser[i].shade), p95(ser[i].shade), median(ser[i].total), p95(ser[i].total),
                  median(ser[i].wall), p95(ser[i].wall), median(ser[i].cpu), median(hits));
    std::printf("| %s | ratio no tile starts / tile starts (quads) | | %.2fx | %.2fx | %.2fx | %.2fx | %.2fx | frames differing: %ld |\n",
                cs.name.c_str(), median(ser[1].march) / median(ser[0].march), median(ser[1].shade) / median(ser[0].shade),
                median(ser[1].total) / median(ser[0].total), median(ser[1].wall) / median(ser[0].wall),
                median(ser[1].cpu) / median(ser[0].cpu), differ);
    std::printf("| %s | ratio 4 per texel / 1 per texel (values binding, tile starts) | | %.2fx | %.2fx | %.2fx | %.2fx | %.2fx | |\n",
                cs.name.c_str(), median(ser[3].march) / median(ser[2].march), median(ser[3].shade) / median(ser[2].shade),
                median(ser[3].total) / median(ser[2].total), median(ser[3].wall) / median(ser[2].wall),
                median(ser[3].cpu) / median(ser[2].cpu));
  }
  std::printf("\nload average after: %s\nverdict: the four configurations' pictures bit-identical: %s\n", load_average().c_str(),
              all_equal ? "PASS" : "FAIL");
  return all_equal ? 0 : 1;
}
