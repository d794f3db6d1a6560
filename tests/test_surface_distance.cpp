// True distance to the trilinear isosurface (eval/surface_distance.h) against analytic truth
// (plane, sphere, a nearly flat field) and against an independent method: OpenVDB's mesh of
// the same volume's isosurface with brute-force point-to-triangle distances.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/engine/cpu_gradient.h"
#include "isotouch/servo/sampling.h"
#include "isotouch/eval/surface_distance.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"

#ifdef ISOTOUCH_HAVE_OPENVDB
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/VolumeToMesh.h>
#endif

using namespace isotouch;
using core::Vec3;

namespace {

const Vec3 kC{0.024, 0.024, 0.024};

// Random points in the box [lo, hi].
Vec3 random_point(std::mt19937_64& rng, Vec3 lo, Vec3 hi) {
  std::uniform_real_distribution<double> u(0, 1);
  return {lo.x + (hi.x - lo.x) * u(rng), lo.y + (hi.y - lo.y) * u(rng), lo.z + (hi.z - lo.z) * u(rng)};
}

}  // namespace

// A plane is exactly linear, so trilinear interpolation reproduces it: the distance is
// |n . (p - c)| up to the float rounding of the sample values (~1e-9 m here).
TEST(SurfaceDistance, PlaneIsExact) {
  const Vec3 n = core::normalized_or(Vec3{0.3, -0.5, 0.8}, {0, 0, 1});
  const Vec3 c{0.016, 0.016, 0.016};
  const core::SampleField f = sim::plane_field(n, c);  // 32^3, 1 mm, value in mm
  std::mt19937_64 rng(7);
  const double tol = 1e-6;  // the default: 1e-3 voxel
  double worst = 0;
  int tested = 0;
  for (int k = 0; k < 120; ++k) {
    const Vec3 p0 = random_point(rng, {0.006, 0.006, 0.006}, {0.026, 0.026, 0.026});
    const Vec3 p = p0 - n * (core::dot(n, p0 - c) * 0.6);  // within 3 mm or so of the plane
    const double exact = std::abs(core::dot(n, p - c));
    const Vec3 foot = p - n * core::dot(n, p - c);
    if (std::min({foot.x, foot.y, foot.z}) < 0.001 || std::max({foot.x, foot.y, foot.z}) > 0.030) continue;
    const eval::SurfaceDistance d = eval::distance_to_isosurface(f, 0.0, p);
    ASSERT_TRUE(d.found) << "p = (" << p.x << ", " << p.y << ", " << p.z << ")";
    EXPECT_GE(d.distance_m, exact - 1e-8);          // a point on the surface: never too small
    EXPECT_LE(d.distance_m, exact + std::min(tol, std::max(1e-9, 1e-2 * exact)) + 1e-8);  // the stated accuracy
    EXPECT_LE(d.lower_bound_m, exact + 1e-8);       // the proven bracket holds the truth
    EXPECT_NEAR(servo::sample_value(f, d.closest_m), 0.0, 1e-4);  // on the surface (value in mm)
    worst = std::max(worst, std::abs(d.distance_m - exact));
    ++tested;
  }
  EXPECT_GT(tested, 50);
  std::printf("plane: %d points, max |d - exact| = %.3g m\n", tested, worst);
}

// Sphere value = 1000 (r - |x - c|) on a 1 mm grid. Trilinear interpolation error of a C2
// function is at most (1/8) sum_a h^2 max|d2f/dx_a^2| (tensor product of 1D linear
// interpolation errors); for |x - c| every second derivative is <= 1/rho, so the
// trilinear isosurface lies within eps = 3 h^2 / (8 rho_min) of the sphere (|grad| = 1),
// rho_min = r - sqrt(3) h - eps for the cells it runs through. The distance to it is then
// within eps of | |p - c| - r |.
TEST(SurfaceDistance, SphereWithinTheTrilinearBound) {
  const double r = 0.015, h = 1e-3;
  const core::SampleField f = sim::sphere_field(kC, r);
  const double eps = 3 * h * h / (8 * (r - std::sqrt(3.0) * h - 0.1 * h));
  std::mt19937_64 rng(11);
  double worst = 0;
  for (int k = 0; k < 300; ++k) {
    const Vec3 p = random_point(rng, kC - Vec3{0.02, 0.02, 0.02}, kC + Vec3{0.02, 0.02, 0.02});
    const double rho = core::norm(p - kC);
    if (std::abs(rho - r) > 0.004) continue;  // within 4 voxels of the surface (cost grows with distance)
    const double exact = std::abs(rho - r);
    const eval::SurfaceDistance d = eval::distance_to_isosurface(f, 0.0, p);
    ASSERT_TRUE(d.found);
    EXPECT_NEAR(d.distance_m, exact, eps + 1e-6) << "rho = " << rho;
    EXPECT_NEAR(servo::sample_value(f, d.closest_m), 0.0, 1e-3);
    worst = std::max(worst, std::abs(d.distance_m - exact));
  }
  std::printf("sphere: max |d - | |p-c| - r | | = %.3g m (bound %.3g m)\n", worst, eps);
}

// The case: a field nearly flat around the point (here 1e-7 units per voxel), the
// surface 6.2 mm away. |f - tau| / |grad f| says kilometres; the true distance is exact
// (the field depends on x only, so the surface is the plane where the x ramp crosses tau).
TEST(SurfaceDistance, FlatFieldGivesTheTrueDistanceNotThousandsOfMm) {
  core::SampleField f;
  f.grid.dims = {40, 12, 12};
  f.grid.spacing_m = {1e-3, 1e-3, 1e-3};
  f.samples.resize(f.grid.voxel_count());
  const double tau = 350;
  auto vx = [&](int i) { return i <= 26 ? float(tau - 1 + 1e-7 * i) : float(tau + 1 + (i - 27)); };
  for (int z = 0; z < 12; ++z)
    for (int y = 0; y < 12; ++y)
      for (int x = 0; x < 40; ++x) f.samples[f.grid.index(x, y, z)] = {vx(x), 0, 0, 0};
  const double v26 = vx(26), v27 = vx(27);
  const double xs = (26 + (tau - v26) / (v27 - v26)) * 1e-3;  // exact crossing on the x ramp
  const Vec3 p{0.0203, 0.0055, 0.0061};
  const double old = eval::first_order_distance(f, tau, p);
  EXPECT_GT(old, 1.0) << "the field must be flat enough to fool the first-order estimate";
  const eval::SurfaceDistance d = eval::distance_to_isosurface(f, tau, p);
  ASSERT_TRUE(d.found);
  EXPECT_NEAR(d.distance_m, xs - p.x, 1e-6 + 1e-9);
  EXPECT_GE(d.distance_m, xs - p.x - 1e-9);
  std::printf("flat field: first-order %.4g m, true %.6g m, found %.6g m (%zu boxes)\n", old, xs - p.x,
              d.distance_m, d.boxes);
}

TEST(SurfaceDistance, NoSurfaceWithinTheRadiusSaysSo) {
  const core::SampleField f = sim::sphere_field(kC, 0.015);
  eval::SurfaceDistanceOptions o;
  o.max_radius_m = 0.003;
  // 10 mm from the sphere surface, searched to 3 mm only.
  const eval::SurfaceDistance d = eval::distance_to_isosurface(f, 0.0, kC + Vec3{0, 0, 0.005}, o);
  EXPECT_FALSE(d.found);
  EXPECT_TRUE(std::isinf(d.distance_m));
  EXPECT_GE(d.lower_bound_m, 0.003 - 1e-12);
  // No crossing at all (isovalue above every value) and bad input: not found, never a number.
  EXPECT_FALSE(eval::distance_to_isosurface(f, 1e6, kC).found);
  EXPECT_FALSE(eval::distance_to_isosurface(f, 0.0, Vec3{NAN, 0, 0}).found);
  // The default radius (64 voxels) reaches a surface 10 mm away.
  const eval::SurfaceDistance far = eval::distance_to_isosurface(f, 0.0, kC + Vec3{0, 0, 0.005});
  ASSERT_TRUE(far.found);
  EXPECT_NEAR(far.distance_m, 0.010, 0.05e-3);
}

#ifdef ISOTOUCH_HAVE_OPENVDB
namespace {
// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = core::dot(ab, ap), d2 = core::dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = core::dot(ab, bp), d4 = core::dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const double d5 = core::dot(ab, cp), d6 = core::dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double den = 1.0 / (va + vb + vc);
  return a + ab * (vb * den) + ac * (vc * den);
}
}  // namespace

// The head CT of scenes/head.json (64 x 64 x 93, spacing 3.2 x 3.2 x 1.5 mm, bone at 1150),
// loaded into an OpenVDB FloatGrid (voxel (i,j,k) = the same value), checked two ways:
// 1. Brute force with OpenVDB's own trilinear sampler (tools::BoxSampler): on a lattice of
//    step s = 0.05 mm around the point, every lattice edge whose end values straddle tau
//    holds an exact surface point (the trilinear field is linear along axis lines), so the
//    nearest such point is within sqrt(3) s (+ float rounding) above the true distance and
//    never below it. distance_to_isosurface must agree within sqrt(3) s + 1e-3 voxel,
//    and no lattice crossing may be nearer than its result minus its tolerance.
// 2. OpenVDB's mesh of the isosurface (tools::volumeToMesh, no adaptivity), distance to it
//    by brute force over all triangles. Its vertices average the edge crossings of a cell,
//    so it is only within a cell of the trilinear surface: the two distances may differ by
//    up to a cell diagonal; printed, and checked against that bound.
namespace {
struct VdbStats {
  double brute_max_vox = 0, mesh_max_vox = 0, mesh_mean_vox = 0;
};
VdbStats compare_with_openvdb(const char* what, const engine::Volume& vol, double tau) {
  VdbStats st;
  const core::SampleField f = engine::compute_samples_cpu(vol);
  const core::Grid& g = f.grid;
  const double hmin = std::min({g.spacing_m.x, g.spacing_m.y, g.spacing_m.z});

  openvdb::initialize();
  openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(float(vol.min_value) - 1.0f);
  auto acc = grid->getAccessor();
  for (int z = 0; z < g.dims[2]; ++z)
    for (int y = 0; y < g.dims[1]; ++y)
      for (int x = 0; x < g.dims[0]; ++x) acc.setValue(openvdb::Coord(x, y, z), vol.voxels[g.index(x, y, z)]);
  openvdb::tools::GridSampler<openvdb::FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> vdb(
      grid->getConstAccessor(), grid->transform());
  auto vdb_value = [&](const Vec3& world_m) {
    const Vec3 i = g.to_index(world_m);
    return double(vdb.isSample(openvdb::Vec3d(i.x, i.y, i.z)));
  };

  std::vector<openvdb::Vec3s> pts;
  std::vector<openvdb::Vec3I> tris;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*grid, pts, tris, quads, tau, 0.0);
  // Index space -> the grid frame [m]; drop faces that reach beyond the border voxel centres
  // (OpenVDB closes the surface against the background there; the trilinear field has no
  // surface outside its box).
  std::vector<Vec3> P(pts.size());
  std::vector<bool> in_box(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    P[i] = g.to_world({pts[i].x(), pts[i].y(), pts[i].z()});
    in_box[i] = pts[i].x() >= 0 && pts[i].y() >= 0 && pts[i].z() >= 0 && double(pts[i].x()) <= g.dims[0] - 1.0 &&
                double(pts[i].y()) <= g.dims[1] - 1.0 && double(pts[i].z()) <= g.dims[2] - 1.0;
  }
  std::vector<std::array<std::uint32_t, 3>> T;
  for (const auto& t : tris)
    if (in_box[t[0]] && in_box[t[1]] && in_box[t[2]]) T.push_back({t[0], t[1], t[2]});
  for (const auto& q : quads)
    if (in_box[q[0]] && in_box[q[1]] && in_box[q[2]] && in_box[q[3]]) {
      T.push_back({q[0], q[1], q[2]});
      T.push_back({q[0], q[2], q[3]});
    }
  EXPECT_GT(T.size(), 1000u);
  if (T.size() < 1000) return st;

  std::mt19937_64 rng(2024);
  std::uniform_int_distribution<std::size_t> pick(0, T.size() - 1);
  std::uniform_real_distribution<double> u(-1, 1);
  const double s = 0.05e-3, tol = 1e-3 * hmin;
  const double cell_diag = core::norm(g.spacing_m);
  double worst_brute = 0, worst_mesh = 0, sum_mesh = 0, worst_on_surface = 0, ms = 0;
  int tested = 0;
  while (tested < 50) {
    // A point within 1 voxel (per axis) of a random mesh vertex, 4 voxels from the border.
    const std::array<std::uint32_t, 3>& t = T[pick(rng)];
    const Vec3 idx{pts[t[0]].x() + u(rng), pts[t[0]].y() + u(rng), pts[t[0]].z() + u(rng)};
    if (idx.x < 4 || idx.y < 4 || idx.z < 4 || idx.x > g.dims[0] - 5 || idx.y > g.dims[1] - 5 || idx.z > g.dims[2] - 5)
      continue;
    const Vec3 p = g.to_world(idx);
    const auto t0 = std::chrono::steady_clock::now();
    const eval::SurfaceDistance d = eval::distance_to_isosurface(f, tau, p);
    ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(d.found);
    if (!d.found) return st;
    worst_on_surface = std::max(worst_on_surface, std::abs(vdb_value(d.closest_m) - tau));
    // 1. Brute force on a lattice, OpenVDB's sampler, in the cube of half-side d + 2 s.
    const double R = d.distance_m + 2 * s;
    const int n = int(std::ceil(2 * R / s));
    double brute = 1e300;
    for (int k = 0; k <= n; ++k)
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
          const Vec3 q = p + Vec3{-R + i * s, -R + j * s, -R + k * s};
          const double a = vdb_value(q) - tau;
          for (const Vec3& e : {Vec3{s, 0, 0}, Vec3{0, s, 0}, Vec3{0, 0, s}}) {
            const double b = vdb_value(q + e) - tau;
            if (a * b > 0) continue;
            const double w = a == b ? 0.0 : a / (a - b);
            brute = std::min(brute, core::norm(q + e * w - p));
          }
        }
    EXPECT_GE(brute, d.distance_m - tol - 1e-7) << "OpenVDB's sampler found a nearer surface point";
    EXPECT_LE(brute, d.distance_m + std::sqrt(3.0) * s + 1e-7) << "no lattice crossing near the point found";
    worst_brute = std::max(worst_brute, std::abs(brute - d.distance_m));
    // 2. The mesh.
    double mesh = 1e300;
    for (const auto& tr : T) mesh = std::min(mesh, core::norm(p - closest_on_triangle(p, P[tr[0]], P[tr[1]], P[tr[2]])));
    EXPECT_LT(std::abs(d.distance_m - mesh), cell_diag);
    worst_mesh = std::max(worst_mesh, std::abs(d.distance_m - mesh));
    sum_mesh += std::abs(d.distance_m - mesh);
    ++tested;
  }
  std::printf("%s, %d points within a voxel of the surface (voxel = %.2f mm smallest):\n"
              "  OpenVDB BoxSampler brute force (lattice %.2f mm): max |d - d_brute| = %.4f voxel (bound %.4f)\n"
              "  OpenVDB volumeToMesh (%zu triangles): |d - d_mesh| max %.4f voxel, mean %.4f voxel (bound: cell diagonal %.2f voxel)\n"
              "  |f_vdb(closest) - tau| max %.3g; %.3f ms per query\n",
              what, tested, hmin * 1e3, s * 1e3, worst_brute / hmin, (std::sqrt(3.0) * s + tol) / hmin, T.size(),
              worst_mesh / hmin, sum_mesh / tested / hmin, cell_diag / hmin, worst_on_surface, ms / tested);
  EXPECT_LT(worst_on_surface, 1e-5 * std::max(std::abs(double(vol.min_value)), std::abs(double(vol.max_value))));
  st.brute_max_vox = worst_brute / hmin;
  st.mesh_max_vox = worst_mesh / hmin;
  st.mesh_mean_vox = sum_mesh / tested / hmin;
  return st;
}
}  // namespace

TEST(SurfaceDistance, AgreesWithOpenVdbOnTheHeadCt) {
  compare_with_openvdb("head CT", io::load_volume(std::string(ISOTOUCH_TEST_DATA) + "/ct-head-headsq/headsq_64x64x93_int16.mhd"), 1150);
}

// A smooth surface: here OpenVDB's mesh is close to the trilinear surface, so the two
// distances must agree closely too: 0.08 voxel, 3x the 0.027 voxel measured, not a cell.
TEST(SurfaceDistance, AgreesWithOpenVdbOnASphere) {
  const VdbStats st = compare_with_openvdb("sphere r = 15 voxels", engine::make_sphere({40, 40, 40}, 1e-3, 15.0), 0.0);
  EXPECT_LT(st.mesh_max_vox, 0.08);
}
#else
TEST(SurfaceDistance, AgreesWithOpenVdbOnTheHeadCt) {
  GTEST_SKIP() << "OpenVDB not found at configure time (Debian: libopenvdb-dev libboost-iostreams-dev libtbb-dev); "
                  "the cross-check against an independent method did not run";
}
#endif

// Anisotropic spacing, checked against a closed form, not only
// against OpenVDB. A linear field f(x) = a . x + b is reproduced exactly by trilinear
// interpolation on any grid, so the isosurface f = 0 is the plane a . x + b = 0 and the
// distance is |a . p + b| / |a|. Voxels 0.7 x 0.7 x 3 mm (a CT with thick slices), oblique
// normal; the search boxes must be measured in metres per axis, not in voxels.
TEST(SurfaceDistance, AnisotropicSpacingPlaneIsExact) {
  const Vec3 h{0.7e-3, 0.7e-3, 3e-3};
  const std::array<int, 3> dims{40, 40, 12};  // 27.3 x 27.3 x 33 mm
  const Vec3 n = core::normalized_or(Vec3{0.4, -0.3, 0.87}, {0, 0, 1});
  const Vec3 c{0.0137, 0.0137, 0.0165};       // a point of the plane
  const Vec3 a = n * 1000.0;                   // value in mm of signed distance
  const engine::Volume vol = engine::make_linear(dims, h, a, -core::dot(a, c));
  const core::SampleField f = engine::compute_samples_cpu(vol);
  std::mt19937_64 rng(23);
  double worst = 0;
  int tested = 0;
  for (int k = 0; k < 80; ++k) {
    const Vec3 p = random_point(rng, {0.004, 0.004, 0.006}, {0.023, 0.023, 0.027});
    const double exact = std::abs(core::dot(n, p - c));
    const Vec3 foot = p - n * core::dot(n, p - c);
    if (exact > 0.003 || std::min({foot.x, foot.y}) < 0.001 || std::max({foot.x, foot.y}) > 0.026 ||
        foot.z < 0.004 || foot.z > 0.029)
      continue;
    const eval::SurfaceDistance d = eval::distance_to_isosurface(f, 0.0, p);
    ASSERT_TRUE(d.found) << "p = (" << p.x << ", " << p.y << ", " << p.z << ")";
    // Stated accuracy: min(1e-3 voxel, max(1e-6 voxel, 1 % of d)), voxel = the smallest spacing.
    const double tol = std::min(0.7e-6, std::max(0.7e-9, 1e-2 * exact)) + 1e-8;
    EXPECT_GE(d.distance_m, exact - 1e-8);
    EXPECT_LE(d.distance_m, exact + tol) << "exact " << exact;
    EXPECT_LE(d.lower_bound_m, exact + 1e-8);
    worst = std::max(worst, std::abs(d.distance_m - exact));
    ++tested;
  }
  EXPECT_GT(tested, 20);
  std::printf("anisotropic plane: %d points, max |d - exact| = %.3g m\n", tested, worst);
}
