// bench_raycast_frames - whole frames of the ray caster (what isotouch-sculpt draws after an
// orbit, pan or zoom) on the head and chest CTs, with the voxels read 4 per texel (quads,
// binding 12) and 1 per texel, measured side by side in one run: the same cameras
// alternating between two casters of the same field, GPU timestamps per pass (median over
// the frames), and whether every frame's picture and depth are bit-identical between the two.
// Usage: bench_raycast_frames [WIDTH HEIGHT FRAMES] (default 1024 768 24)
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "raycast.h"
#include "picture.h"
#include "scene.h"
#include "vk_context.h"

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
  std::printf("| scene | voxels read as | march median / p95 [ms] | shade median / p95 [ms] | march + shade median [ms] | "
              "hit pixels (median) |\n|---|---|---|---|---|---|\n");
  bool all_equal = true;
  for (const char* name : {"head.json", "chest.json"}) {
    std::filesystem::path p = std::filesystem::path("scenes") / name;
    if (!std::filesystem::exists(p)) p = std::filesystem::path(ISOTOUCH_SOURCE_DIR) / "scenes" / name;
    const io::Scene scene = io::load_scene(p.string());
    const engine::Volume vol = run::load_scene_volume(scene);
    const engine::RaycastField field = run::scene_raycast_field(scene, vol);
    auto q = engine::RayCaster::create(vk, field, true), s = engine::RayCaster::create(vk, field, false);
    if (!q || !s) {
      std::fprintf(stderr, "bench_raycast_frames: %s\n", (!q ? q.error : s.error).c_str());
      return 1;
    }
    engine::RayCaster* casters[2] = {q.value->get(), s.value->get()};
    std::vector<double> march[2], shade[2], total[2], hits;
    long differ = 0;
    engine::OrbitCamera cam = run::default_camera(vol);
    for (int f = 0; f <= frames; ++f) {  // frame 0: warm-up
      cam.azimuth_deg += 3;
      cam.zoom *= 1.02;
      const engine::CameraView view = engine::orbit_view(vol.grid, vol.direction, cam);
      engine::RaycastImage img[2];
      for (int k = 0; k < 2; ++k) {
        const int i = (f + k) % 2;  // alternate which goes first
        img[i] = casters[i]->render(view, engine::RaycastStyle{}, width, height);
      }
      if (f == 0) continue;
      for (int i = 0; i < 2; ++i) {
        march[i].push_back(img[i].march_ms);
        shade[i].push_back(img[i].shade_ms);
        total[i].push_back(img[i].march_ms + img[i].shade_ms);
      }
      hits.push_back(double(std::count_if(img[0].depth.begin(), img[0].depth.end(), [](float t) { return t >= 0; })));
      if (img[0].rgba != img[1].rgba || std::memcmp(img[0].depth.data(), img[1].depth.data(), img[0].depth.size() * 4) != 0)
        ++differ;
    }
    all_equal = all_equal && differ == 0;
    for (int i = 0; i < 2; ++i)
      std::printf("| %s | %s | %.1f / %.1f | %.1f / %.1f | %.1f | %.0f |\n", scene.name.c_str(),
                  i == 0 ? (casters[0]->quads() ? "quads (4 per texel)" : "1 per texel (quads did not fit)") : "1 per texel",
                  median(march[i]), p95(march[i]), median(shade[i]), p95(shade[i]), median(total[i]), median(hits));
    std::printf("| %s | ratio 1-float / quads | %.2fx | %.2fx | %.2fx | frames differing: %ld |\n", scene.name.c_str(),
                median(march[1]) / median(march[0]), median(shade[1]) / median(shade[0]),
                median(total[1]) / median(total[0]), differ);
  }
  std::printf("\nload average after: %s\nverdict: quads and 1-float pictures bit-identical: %s\n", load_average().c_str(),
              all_equal ? "PASS" : "FAIL");
  return all_equal ? 0 : 1;
}
