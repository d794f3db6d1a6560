#include "isotouch/engine/synthetic.h"

#include <cmath>
#include <random>
#include <sstream>

namespace isotouch::engine {
namespace {
Volume blank(std::array<int, 3> dims, core::Vec3 spacing, const std::string& name) {
  for (int a = 0; a < 3; ++a)
    if (dims[std::size_t(a)] <= 0) throw VolumeError(name + ": dimensions must be positive");
  Volume v;
  v.grid.dims = dims;
  v.grid.spacing_m = spacing;
  v.grid.origin_m = {0, 0, 0};
  v.voxels.resize(v.grid.voxel_count());
  v.path = name;
  v.reader = "synthetic";
  v.component_type = "float";
  return v;
}
}  // namespace

Volume make_sphere(std::array<int, 3> dims, double h, double radius_vox,
                   std::array<double, 3> off) {
  std::ostringstream name;
  name << "synthetic:sphere(" << dims[0] << "x" << dims[1] << "x" << dims[2]
       << ",r=" << radius_vox << "vox)";
  Volume v = blank(dims, {h, h, h}, name.str());
  const core::Vec3 c = v.grid.centre_m() + core::Vec3{off[0], off[1], off[2]} * h;
  const double r = radius_vox * h;
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x) {
        const core::Vec3 p = v.grid.to_world({double(x), double(y), double(z)});
        v.voxels[v.grid.index(x, y, z)] = float((r - core::norm(p - c)) * 1000.0);
      }
  v.update_stats();
  return v;
}

Volume make_linear(std::array<int, 3> dims, core::Vec3 spacing, core::Vec3 a, double b) {
  Volume v = blank(dims, spacing, "synthetic:linear");
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x)
        v.voxels[v.grid.index(x, y, z)] =
            float(core::dot(a, v.grid.to_world({double(x), double(y), double(z)})) + b);
  v.update_stats();
  return v;
}

Volume make_random(std::array<int, 3> dims, core::Vec3 spacing, float lo, float hi,
                   std::uint32_t seed) {
  Volume v = blank(dims, spacing, "synthetic:random");
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, hi);
  for (float& f : v.voxels) f = u(rng);
  v.update_stats();
  return v;
}

}  // namespace isotouch::engine
