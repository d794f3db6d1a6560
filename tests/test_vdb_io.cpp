// test_vdb_io.cpp - OpenVDB in and out, mesh export (io/vdb_io.h).
// Truth from outside the code under test: analytic spheres (area 4 pi r^2, volume), brute
// force edge counts, our own tiny STL/OBJ/PLY readers, OpenVDB's own level-set sphere, and
// a child process killed with SIGKILL while it saves. OpenVDB only through io/vdb_io.h.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <set>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <sstream>
#include <thread>

#include "isotouch/run/export.h"
#include "isotouch/tests/memory_limited_child.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_io.h"

extern char** environ;

namespace isotouch::run {
using core::dot;
using io::LoadedVdb;
using io::Mesh;
using io::MeshStats;
using io::VdbError;
using io::extract_mesh;
using io::load_vdb;
using io::mesh_stats;
using io::save_vdb;
using io::write_obj;
using io::write_ply;
using io::write_stl_binary;
using io::write_test_vdb;
using io::TestVdb;
namespace {

namespace fs = std::filesystem;
using core::InsideIs;
using core::Isosurface;

/// A fresh folder per test (removed at the end).
struct TempDir {
  fs::path dir;
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir = fs::temp_directory_path() /
          ("isotouch_vdb_io_" + std::to_string(::getpid()) + "_" + info->test_suite_name() + "_" + info->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::string operator/(const std::string& name) const { return (dir / name).string(); }
};

/// Exact equality of two volumes: every voxel bit for bit, the grid bit for bit, direction.
void expect_identical(const engine::Volume& a, const engine::Volume& b) {
  ASSERT_EQ(a.grid.dims, b.grid.dims);
  for (int k = 0; k < 3; ++k) {  // bit for bit (== would let -0.0 pass for 0.0)
    const double sa = (&a.grid.spacing_m.x)[k], sb = (&b.grid.spacing_m.x)[k];
    const double oa = (&a.grid.origin_m.x)[k], ob = (&b.grid.origin_m.x)[k];
    EXPECT_EQ(0, std::memcmp(&sa, &sb, sizeof sa)) << "spacing axis " << k << ": " << sa << " vs " << sb;
    EXPECT_EQ(0, std::memcmp(&oa, &ob, sizeof oa)) << "origin axis " << k << ": " << oa << " vs " << ob;
  }
  EXPECT_EQ(a.direction, b.direction);
  EXPECT_EQ(a.direction_is_identity, b.direction_is_identity);
  ASSERT_EQ(a.voxels.size(), b.voxels.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < a.voxels.size(); ++i)
    differ += std::memcmp(&a.voxels[i], &b.voxels[i], sizeof(float)) != 0;
  EXPECT_EQ(differ, 0u) << "voxels differing bitwise";
}

bool voxels_bitwise_equal(const engine::Volume& a, const engine::Volume& b) {
  return a.voxels.size() == b.voxels.size() &&
         std::memcmp(a.voxels.data(), b.voxels.data(), a.voxels.size() * sizeof(float)) == 0;
}

/// Expects `f` to throw VdbError whose message holds every one of `parts`.
template <typename F>
void expect_error(F&& f, std::initializer_list<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "no error thrown; expected one naming " << *parts.begin();
  } catch (const VdbError& e) {
    const std::string m = e.what();
    for (const auto& p : parts) EXPECT_NE(m.find(p), std::string::npos) << "message '" << m << "' lacks '" << p << "'";
  } catch (const std::exception& e) {
    ADD_FAILURE() << "threw something other than VdbError: " << e.what();
  }
}

// ------------------------------------------------------------------------ round trip

TEST(VdbIo, SyntheticRoundTripIsBitIdentical) {
  TempDir tmp;
  engine::Volume v = engine::make_random({37, 20, 11}, {0.7e-3, 0.5e-3, 1.3e-3}, -5.0f, 7.0f, 1234);
  v.grid.origin_m = {-0.0123, 0.0456, 1.5e-3};
  v.voxels[0] = std::numeric_limits<float>::quiet_NaN();
  v.voxels[1] = -0.0f;
  v.voxels[2] = std::numeric_limits<float>::infinity();
  v.voxels[3] = -std::numeric_limits<float>::infinity();
  v.voxels[4] = std::numeric_limits<float>::denorm_min();
  v.voxels[5] = 0.0f;
  v.direction = {0, 1, 0, 0, 0, 1, 1, 0, 0};  // a rotation (axes permuted)
  v.direction_is_identity = false;
  v.update_stats();
  const std::string path = tmp / "synthetic.vdb";
  save_vdb(v, path);
  const LoadedVdb l = load_vdb(path);
  expect_identical(v, l.volume);
  EXPECT_EQ(l.volume.path, path);
  EXPECT_EQ(l.source_path, v.path);
  EXPECT_FALSE(l.suggested.has_value()) << "no isosurface was saved";
  EXPECT_TRUE(l.written_by_isotouch);
  EXPECT_EQ(l.grid_name, "volume");
  EXPECT_EQ(l.volume.nan_voxels, 1u);
  EXPECT_EQ(l.volume.inf_voxels, 2u);
  EXPECT_EQ(l.volume.min_value, v.min_value);
  EXPECT_EQ(l.volume.max_value, v.max_value);
  // Saved again from the loaded copy: the same voxels again (a second generation).
  save_vdb(l.volume, path, {.grid_name = "again", .iso = Isosurface{0.5, InsideIs::kBelow}, .source_path = "x"});
  const LoadedVdb l2 = load_vdb(path, "again");
  expect_identical(v, l2.volume);
  ASSERT_TRUE(l2.suggested.has_value());
  EXPECT_EQ(l2.suggested->tau, 0.5);
  EXPECT_EQ(l2.suggested->inside, InsideIs::kBelow);
  EXPECT_EQ(l2.source_path, "x");
}

TEST(VdbIo, HeadCtRoundTripIsBitIdentical) {
  TempDir tmp;
  const std::string src = std::string(ISOTOUCH_TEST_DATA) + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
  const engine::Volume v = io::load_volume(src);
  const std::string path = tmp / "head.vdb";
  save_vdb(v, path, {.grid_name = "ct", .iso = Isosurface{1150, InsideIs::kAbove}, .source_path = ""});
  const LoadedVdb l = load_vdb(path);
  expect_identical(v, l.volume);
  EXPECT_EQ(l.grid_name, "ct");
  EXPECT_EQ(l.source_path, src);
  ASSERT_TRUE(l.suggested.has_value());
  EXPECT_EQ(l.suggested->tau, 1150.0);
  EXPECT_EQ(l.suggested->inside, InsideIs::kAbove);
  // The reader is OpenVDB's (what summary.json says), the first one in brackets, once.
  EXPECT_EQ(l.volume.reader, "openvdb:FloatGrid (converted from itk:MetaImageIO)");
  save_vdb(l.volume, tmp / "again.vdb");
  EXPECT_EQ(load_vdb(tmp / "again.vdb").volume.reader, "openvdb:FloatGrid (converted from itk:MetaImageIO)");
  fs::remove(tmp / "again.vdb");
  EXPECT_EQ(l.volume.component_type, v.component_type);
  EXPECT_EQ(l.volume.min_value, v.min_value);
  EXPECT_EQ(l.volume.max_value, v.max_value);
  // The background outside the volume (what OpenVDB tools read there) is outside the bone.
  EXPECT_LE(l.background, 1150.0f);
  // Nothing but the target is left in the folder (no temp file).
  std::size_t files = 0;
  for (const auto& e : fs::directory_iterator(tmp.dir)) files += e.path().filename() != "head.vdb";
  EXPECT_EQ(files, 0u);
}

// ------------------------------------------------------------------------ SIGKILL

/// A large volume (160^3 = 4.1 M voxels, 16 MB) of pseudo-random floats (they do not
/// compress, so a save takes a while), different for each seed.
engine::Volume big_volume(std::uint32_t seed) {
  return engine::make_random({160, 160, 160}, {1e-3, 1e-3, 1e-3}, -1000.0f, 1000.0f, seed);
}

// The child: saves the seed-2 volume over ISOTOUCH_VDB_SAVE_LOOP again and again, writing
// one byte to fd 3 before each save. Skipped unless run by the SIGKILL test below.
TEST(VdbIoSigkill, ChildSaveLoop) {
  const char* target = std::getenv("ISOTOUCH_VDB_SAVE_LOOP");
  if (!target) GTEST_SKIP() << "helper process of VdbIoSigkill.KilledMidSaveLeavesOldOrNewFile";
  const engine::Volume v = big_volume(2);
  for (int i = 0; i < 1000; ++i) {
    if (::write(3, "s", 1) != 1) std::_Exit(3);
    save_vdb(v, target);
  }
  std::_Exit(0);
}

TEST(VdbIoSigkill, KilledMidSaveLeavesOldOrNewFile) {
  TempDir tmp;
  const std::string target = tmp / "sculpt.vdb";
  const engine::Volume old_v = big_volume(1), new_v = big_volume(2);
  ASSERT_FALSE(voxels_bitwise_equal(old_v, new_v));
  const auto t0 = std::chrono::steady_clock::now();
  save_vdb(old_v, target);
  const double save_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("one save of 160^3 floats: %.3f s\n", save_s);

  const std::string prefix = "sculpt.vdb.tmp-";
  std::mt19937 rng(20261121);
  const int trials = 6;
  int killed_with_temp = 0, saw_old = 0, saw_new = 0;
  for (int trial = 0; trial < trials; ++trial) {
    if (trial > 0) save_vdb(old_v, target);  // each trial starts from the old content
    int fds[2];
    ASSERT_EQ(::pipe(fds), 0);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addclose(&fa, fds[0]);  // first: the read end may be fd 3 itself
    posix_spawn_file_actions_adddup2(&fa, fds[1], 3);
    const std::string env_target = "ISOTOUCH_VDB_SAVE_LOOP=" + target;
    std::vector<char*> env;
    for (char** e = environ; *e; ++e) env.push_back(*e);
    env.push_back(const_cast<char*>(env_target.c_str()));
    env.push_back(nullptr);
    std::string exe = fs::read_symlink("/proc/self/exe").string();
    std::string filter = "--gtest_filter=VdbIoSigkill.ChildSaveLoop";
    char* argv[] = {exe.data(), filter.data(), nullptr};
    pid_t pid = 0;
    ASSERT_EQ(posix_spawn(&pid, exe.c_str(), &fa, nullptr, argv, env.data()), 0);
    posix_spawn_file_actions_destroy(&fa);
    ::close(fds[1]);
    // Let the child run 1 to 3 saves; wait for the start of the last one.
    const int saves = 1 + int(rng() % 3);
    for (int s = 0; s < saves; ++s) {
      pollfd p{fds[0], POLLIN, 0};
      ASSERT_EQ(::poll(&p, 1, 120000), 1) << "child never started saving";
      char c;
      ASSERT_EQ(::read(fds[0], &c, 1), 1);
    }
    // Poll until the temp file appears (at most 2 save times), then a random moment
    // within the save (sometimes just after it) and SIGKILL.
    bool temp_seen = false;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(2 * save_s + 0.5);
    while (!temp_seen && std::chrono::steady_clock::now() < deadline) {
      for (const auto& e : fs::directory_iterator(tmp.dir))
        temp_seen |= e.path().filename().string().rfind(prefix, 0) == 0;
      if (!temp_seen) std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    std::uniform_real_distribution<double> when(0.0, 1.1 * save_s);
    std::this_thread::sleep_for(std::chrono::duration<double>(when(rng)));
    bool temp_at_kill = false;
    for (const auto& e : fs::directory_iterator(tmp.dir))
      temp_at_kill |= e.path().filename().string().rfind(prefix, 0) == 0;
    ASSERT_EQ(::kill(pid, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ::close(fds[0]);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << "the child ended before the kill";
    killed_with_temp += temp_at_kill;

    // The target loads, whole, and is the old content or the new one.
    try {
      const LoadedVdb l = load_vdb(target);
      const bool is_old = voxels_bitwise_equal(l.volume, old_v), is_new = voxels_bitwise_equal(l.volume, new_v);
      EXPECT_TRUE(is_old || is_new) << "trial " << trial << ": target is neither the old nor the new content";
      saw_old += is_old;
      saw_new += is_new;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "trial " << trial << ": torn target after SIGKILL: " << e.what();
    }
    // Left-overs are temp files, never named like the target (and not *.vdb); remove them.
    for (const auto& e : fs::directory_iterator(tmp.dir)) {
      const std::string name = e.path().filename().string();
      if (name == "sculpt.vdb") continue;
      EXPECT_EQ(name.rfind(prefix, 0), 0u) << "unexpected file " << name;
      EXPECT_NE(e.path().extension(), ".vdb") << name;
      fs::remove(e.path());
    }
    std::printf("trial %d: killed in save %d, %s\n", trial, saves,
                temp_at_kill ? "temp file present (mid-save)" : "no temp file (between saves)");
  }
  std::printf("%d trials: %d killed mid-save (temp file present), target old %d, new %d\n", trials, killed_with_temp,
              saw_old, saw_new);
  EXPECT_GE(killed_with_temp, 1) << "no kill landed inside a save: the test did not test anything";
}

// ------------------------------------------------------------------------ meshes

/// Sphere of radius r_vox voxels around the grid centre as a signed distance [mm]:
/// negative inside for kBelow, positive inside for kAbove.
engine::Volume sdf_sphere(int n, double spacing_m, double r_vox, InsideIs inside) {
  engine::Volume v;
  v.grid.dims = {n, n, n};
  v.grid.spacing_m = {spacing_m, spacing_m, spacing_m};
  v.grid.origin_m = {0.01, -0.02, 0.03};
  v.path = "synthetic:sdf-sphere";
  v.reader = "synthetic";
  v.voxels.resize(v.grid.voxel_count());
  const double c = (n - 1) / 2.0;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double d = (std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c)) - r_vox) * spacing_m * 1e3;
        v.voxels[v.grid.index(x, y, z)] = float(inside == InsideIs::kBelow ? d : -d);
      }
  v.update_stats();
  return v;
}

/// Brute force: every undirected edge (vertex index pair) and how many triangles hold it.
std::map<std::pair<std::uint32_t, std::uint32_t>, int> edge_counts(const std::vector<std::array<std::uint32_t, 3>>& tris) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> e;
  for (const auto& t : tris)
    for (int k = 0; k < 3; ++k) {
      const auto a = t[std::size_t(k)], b = t[std::size_t((k + 1) % 3)];
      ++e[{std::min(a, b), std::max(a, b)}];
    }
  return e;
}

bool closed(const std::vector<std::array<std::uint32_t, 3>>& tris) {
  const auto e = edge_counts(tris);
  if (e.empty()) return false;
  for (const auto& [k, n] : e)
    if (n != 2) return false;
  return true;
}

struct Figures {
  double area = 0, volume = 0;
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
};
Figures figures(const std::vector<std::array<double, 3>>& v, const std::vector<std::array<std::uint32_t, 3>>& tris) {
  Figures f;
  for (const auto& p : v)
    for (int a = 0; a < 3; ++a) f.lo[a] = std::min(f.lo[a], p[a]), f.hi[a] = std::max(f.hi[a], p[a]);
  for (const auto& t : tris) {
    const auto &a = v[t[0]], &b = v[t[1]], &c = v[t[2]];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    f.area += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    f.volume += (a[0] * n[0] + a[1] * n[1] + a[2] * n[2]) / 6.0;  // (a . ((b - a) x (c - a))) / 6
  }
  return f;
}

// Tiny readers, independent of the writers (binary STL, OBJ, binary little-endian PLY).
struct ReadMesh {
  /// The text the file gives besides the geometry: STL's 80-byte header (up to its first
  /// zero byte), OBJ's first line if a comment, PLY's comment lines (joined by newlines).
  std::string header;
  std::vector<std::array<double, 3>> v;
  std::vector<std::array<std::uint32_t, 3>> t;
  std::vector<std::array<float, 3>> facet_normal;  // STL only
};

ReadMesh read_stl(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), {});
  ReadMesh m;
  if (bytes.size() < 84) return m;
  m.header = bytes.substr(0, std::min(bytes.find('\0'), std::size_t(80)));
  std::uint32_t n;
  std::memcpy(&n, bytes.data() + 80, 4);
  EXPECT_EQ(bytes.size(), 84 + 50 * std::size_t(n)) << path << ": size is not 84 + 50 x triangles";
  if (bytes.size() != 84 + 50 * std::size_t(n)) return m;
  for (std::uint32_t i = 0; i < n; ++i) {
    float f[12];
    std::memcpy(f, bytes.data() + 84 + 50 * std::size_t(i), sizeof f);
    m.facet_normal.push_back({f[0], f[1], f[2]});
    for (int k = 0; k < 3; ++k) m.v.push_back({f[3 + 3 * k], f[4 + 3 * k], f[5 + 3 * k]});
    m.t.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  return m;
}

ReadMesh read_obj(const std::string& path) {
  std::ifstream in(path);
  ReadMesh m;
  std::string line;
  for (bool first = true; std::getline(in, line); first = false) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (first && tag.rfind('#', 0) == 0) m.header = line;
    if (tag == "v") {
      std::array<double, 3> p{};
      s >> p[0] >> p[1] >> p[2];
      m.v.push_back(p);
    } else if (tag == "f") {
      std::vector<std::uint32_t> idx;
      std::string tok;
      while (s >> tok) idx.push_back(std::uint32_t(std::stoul(tok.substr(0, tok.find('/'))) - 1));
      EXPECT_EQ(idx.size(), 3u) << path << ": a face that is not a triangle";
      if (idx.size() == 3) m.t.push_back({idx[0], idx[1], idx[2]});
    }
  }
  return m;
}

ReadMesh read_ply(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  ReadMesh m;
  std::string line, format;
  std::size_t nv = 0, nf = 0;
  std::vector<std::string> vprops;  // "float x" ...
  std::string face_count_type, face_index_type, current;
  std::getline(in, line);
  EXPECT_EQ(line, "ply");
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream s(line);
    std::string w;
    s >> w;
    if (w == "format") s >> format;
    if (w == "comment") m.header += line + "\n";
    if (w == "element") {
      std::size_t n = 0;
      s >> current >> n;
      (current == "vertex" ? nv : nf) = n;
    }
    if (w == "property" && current == "vertex") {
      std::string type, name;
      s >> type >> name;
      vprops.push_back(type);
    }
    if (w == "property" && current == "face") {
      std::string list;
      s >> list >> face_count_type >> face_index_type;
    }
  }
  EXPECT_EQ(format, "binary_little_endian");
  for (const auto& t : vprops) EXPECT_TRUE(t == "float" || t == "float32") << "vertex property type " << t;
  EXPECT_TRUE(face_count_type == "uchar" || face_count_type == "uint8") << face_count_type;
  EXPECT_TRUE(face_index_type == "int" || face_index_type == "uint" || face_index_type == "int32" ||
              face_index_type == "uint32") << face_index_type;
  std::vector<float> rec(vprops.size());
  for (std::size_t i = 0; i < nv && in; ++i) {
    in.read(reinterpret_cast<char*>(rec.data()), std::streamsize(rec.size() * 4));
    m.v.push_back({rec[0], rec[1], rec[2]});  // x y z first
  }
  for (std::size_t i = 0; i < nf && in; ++i) {
    unsigned char k = 0;
    in.read(reinterpret_cast<char*>(&k), 1);
    EXPECT_EQ(k, 3) << "face " << i << " is not a triangle";
    std::uint32_t idx[3] = {0, 0, 0};
    in.read(reinterpret_cast<char*>(idx), 12);
    m.t.push_back({idx[0], idx[1], idx[2]});
  }
  EXPECT_TRUE(bool(in)) << path << ": truncated";
  in.get();
  EXPECT_TRUE(in.eof()) << path << ": bytes after the last face";
  return m;
}

/// Checks the sphere mesh of `v` (radius r [m], centre `centre_mm` in the physical frame,
/// LPS, in mm) against the analytic sphere, then the three files written from it against
/// the sphere in millimetres and against the mesh.
void check_sphere_mesh(const engine::Volume& v, const Isosurface& iso, double r, const std::array<double, 3>& centre_mm,
                       const TempDir& tmp) {
  const Mesh mesh = extract_mesh(v, iso);
  ASSERT_GT(mesh.triangles.size(), 1000u);
  // Closed: every undirected edge in exactly two triangles (brute force).
  const auto edges = edge_counts(mesh.triangles);
  std::size_t bad = 0;
  for (const auto& [e, n] : edges) bad += n != 2;
  EXPECT_EQ(bad, 0u) << "edges not shared by exactly two triangles, of " << edges.size();
  const Figures f = figures(mesh.vertices, mesh.triangles);
  const double area = 4 * std::numbers::pi * r * r, volume = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  std::printf("sphere r = %.1f mm (inside %s): %zu triangles, area %.6g m^2 (4 pi r^2 %.6g, %+.3f %%), "
              "signed volume %.6g m^3 (%+.3f %%)\n",
              r * 1e3, core::to_string(iso.inside), mesh.triangles.size(), f.area, area, 100 * (f.area / area - 1),
              f.volume, 100 * (f.volume / volume - 1));
  EXPECT_NEAR(f.area / area, 1.0, 0.01);
  EXPECT_GT(f.volume, 0.0) << "triangles face inward";
  EXPECT_NEAR(f.volume / volume, 1.0, 0.02);
  // mesh_stats (used by the CLI) agrees with the brute force.
  const MeshStats st = mesh_stats(mesh);
  EXPECT_TRUE(st.closed());
  EXPECT_NEAR(st.area_m2, f.area, 1e-9 * f.area);
  EXPECT_NEAR(st.signed_volume_m3, f.volume, 1e-9 * std::abs(f.volume));

  write_stl_binary(mesh, tmp / "s.stl");
  write_obj(mesh, tmp / "s.obj");
  write_ply(mesh, tmp / "s.ply");
  const std::pair<const char*, ReadMesh> files[] = {
      {"stl", read_stl(tmp / "s.stl")}, {"obj", read_obj(tmp / "s.obj")}, {"ply", read_ply(tmp / "s.ply")}};
  // The files hold millimetres in LPS (the volume's physical frame), and say so.
  const double r_mm = r * 1e3;
  for (const auto& [what, m] : files) {
    SCOPED_TRACE(what);
    EXPECT_NE(m.header.find("SPACE=LPS"), std::string::npos) << m.header;
    EXPECT_NE(m.header.find("UNITS=mm"), std::string::npos) << m.header;
    EXPECT_EQ(m.t.size(), mesh.triangles.size());
    const Figures g = figures(m.v, m.t);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR((g.hi[a] - g.lo[a]) / 2, r_mm, 0.01 * r_mm) << "axis " << a << ": the sphere's radius in mm";
      EXPECT_NEAR((g.hi[a] + g.lo[a]) / 2, centre_mm[a], 0.01 * r_mm) << "axis " << a << ": its centre in LPS mm";
      EXPECT_NEAR(g.lo[a], f.lo[a] * 1e3, 1e-4);  // float32 coordinates of ~50 mm: ~4e-6 mm
      EXPECT_NEAR(g.hi[a], f.hi[a] * 1e3, 1e-4);
    }
    EXPECT_NEAR(g.area / (4 * std::numbers::pi * r_mm * r_mm), 1.0, 0.01) << "area in mm^2";
    EXPECT_NEAR(g.area / (f.area * 1e6), 1.0, 1e-5);
    EXPECT_NEAR(g.volume / (f.volume * 1e9), 1.0, 1e-5) << "winding changed in the file";
    if (std::string(what) != "stl") {
      EXPECT_TRUE(closed(m.t)) << "shared vertices lost";
    }
  }
  // STL facet normals: unit, and the right-hand normal of their triangle.
  const ReadMesh& stl = files[0].second;
  std::size_t wrong = 0;
  for (std::size_t i = 0; i < stl.t.size(); ++i) {
    const auto &a = stl.v[3 * i], &b = stl.v[3 * i + 1], &c = stl.v[3 * i + 2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const auto& fn = stl.facet_normal[i];
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len == 0) continue;
    const double dot = (n[0] * fn[0] + n[1] * fn[1] + n[2] * fn[2]) / len;
    wrong += dot < 0.999 || std::abs(std::hypot(fn[0], fn[1], fn[2]) - 1.0) > 1e-5;
  }
  EXPECT_EQ(wrong, 0u) << "STL facet normals that are not the unit right-hand normal";
}

/// sdf_sphere's centre, physical = origin + D (spacing * index) at index (n - 1) / 2 on
/// each axis, in mm.
std::array<double, 3> sphere_centre_mm(const engine::Volume& v) {
  const double c = (v.grid.dims[0] - 1) / 2.0 * v.grid.spacing_m.x;  // cubic grid, equal spacing
  const auto& d = v.direction;  // row-major
  const double o[3] = {v.grid.origin_m.x, v.grid.origin_m.y, v.grid.origin_m.z};
  std::array<double, 3> p{};
  for (int i = 0; i < 3; ++i) p[i] = 1e3 * (o[i] + c * (d[3 * i] + d[3 * i + 1] + d[3 * i + 2]));
  return p;
}

TEST(VdbMesh, SdfSphereInsideBelowIsClosedWithTheRightAreaFacingOut) {
  TempDir tmp;
  const engine::Volume v = sdf_sphere(52, 1e-3, 20.0, InsideIs::kBelow);
  check_sphere_mesh(v, {0.0, InsideIs::kBelow}, 20e-3, sphere_centre_mm(v), tmp);
}

TEST(VdbMesh, SdfSphereInsideAboveIsClosedWithTheRightAreaFacingOut) {
  TempDir tmp;
  const engine::Volume v = sdf_sphere(52, 0.5e-3, 20.0, InsideIs::kAbove);
  check_sphere_mesh(v, {0.0, InsideIs::kAbove}, 10e-3, sphere_centre_mm(v), tmp);
}

// A volume turned 90 degrees about z (index x along physical +y, index y along -x) with its
// origin off zero: the files hold the sphere where the direction matrix puts it, in LPS mm.
TEST(VdbMesh, RotatedVolumeMeshIsInLpsMillimetres) {
  TempDir tmp;
  engine::Volume v = sdf_sphere(52, 1e-3, 20.0, InsideIs::kBelow);
  v.grid.origin_m = {0.1, -0.05, 0.2};
  v.direction = {0, -1, 0, 1, 0, 0, 0, 0, 1};
  v.direction_is_identity = false;
  const std::array<double, 3> c = sphere_centre_mm(v);
  EXPECT_NEAR(c[0], 100 - 25.5, 1e-9);  // 0.1 m - 25.5 voxels of 1 mm along -x
  EXPECT_NEAR(c[1], -50 + 25.5, 1e-9);
  check_sphere_mesh(v, {0.0, InsideIs::kBelow}, 20e-3, c, tmp);
}

// --mesh-units m: the same files in metres, and their headers say so.
TEST(VdbMesh, MetresOnRequest) {
  TempDir tmp;
  const engine::Volume v = sdf_sphere(52, 1e-3, 20.0, InsideIs::kBelow);
  const Mesh mesh = extract_mesh(v, {0.0, InsideIs::kBelow});
  write_stl_binary(mesh, tmp / "m.stl", io::MeshUnits::kMetre);
  write_obj(mesh, tmp / "m.obj", io::MeshUnits::kMetre);
  write_ply(mesh, tmp / "m.ply", io::MeshUnits::kMetre);
  const std::pair<const char*, ReadMesh> files[] = {
      {"stl", read_stl(tmp / "m.stl")}, {"obj", read_obj(tmp / "m.obj")}, {"ply", read_ply(tmp / "m.ply")}};
  const std::array<double, 3> c = sphere_centre_mm(v);
  for (const auto& [what, m] : files) {
    SCOPED_TRACE(what);
    EXPECT_NE(m.header.find("SPACE=LPS UNITS=m"), std::string::npos) << m.header;
    EXPECT_EQ(m.header.find("UNITS=mm"), std::string::npos) << m.header;
    const Figures g = figures(m.v, m.t);
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR((g.hi[a] - g.lo[a]) / 2, 20e-3, 0.01 * 20e-3) << "axis " << a << ": the radius in m";
      EXPECT_NEAR((g.hi[a] + g.lo[a]) / 2, c[a] * 1e-3, 0.01 * 20e-3) << "axis " << a;
    }
  }
}

// A mirroring direction matrix (det D = -1): the mesh in the physical frame still faces out.
TEST(VdbMesh, MirroredDirectionStillFacesOut) {
  engine::Volume v = sdf_sphere(52, 1e-3, 20.0, InsideIs::kBelow);
  v.direction = {-1, 0, 0, 0, 1, 0, 0, 0, 1};
  v.direction_is_identity = false;
  const Mesh m = extract_mesh(v, {0.0, InsideIs::kBelow});
  EXPECT_TRUE(closed(m.triangles));
  EXPECT_GT(figures(m.vertices, m.triangles).volume, 0.0);
}

// An object that fills the grid: closed at the border (the outside reads as outside), facing out.
TEST(VdbMesh, ObjectTouchingTheBorderIsClosed) {
  engine::Volume v = engine::make_linear({12, 9, 7}, {1e-3, 1e-3, 1e-3}, {0, 0, 0}, 5.0);  // 5 everywhere
  for (const auto inside : {InsideIs::kAbove, InsideIs::kBelow}) {
    const Isosurface iso{inside == InsideIs::kAbove ? 1.0 : 9.0, inside};
    const Mesh m = extract_mesh(v, iso);
    EXPECT_TRUE(closed(m.triangles)) << core::to_string(inside);
    const Figures f = figures(m.vertices, m.triangles);
    EXPECT_GT(f.volume, 0.0) << core::to_string(inside);
    // The surface closes half a voxel beyond the border voxels' centres: 12 x 9 x 7 mm.
    EXPECT_NEAR(f.hi[0] - f.lo[0], 12e-3, 1e-9);
    EXPECT_NEAR(f.hi[1] - f.lo[1], 9e-3, 1e-9);
    EXPECT_NEAR(f.hi[2] - f.lo[2], 7e-3, 1e-9);
    // A box whose edges and corners are bevelled (one vertex per cell): a little less than
    // 12 x 9 x 7 mm^3, more than the box minus a 1 mm deep bevel band along its 12 edges.
    EXPECT_LT(f.volume, 12e-3 * 9e-3 * 7e-3);
    EXPECT_GT(f.volume, 12e-3 * 9e-3 * 7e-3 - 4 * (12e-3 + 9e-3 + 7e-3) * 0.5e-6);
  }
  // Nothing inside: no mesh, and the writers refuse to write an empty file.
  const Mesh none = extract_mesh(v, {10.0, InsideIs::kAbove});
  EXPECT_TRUE(none.triangles.empty());
  TempDir tmp;
  expect_error([&] { write_stl_binary(none, tmp / "none.stl"); }, {"none.stl", "empty"});
  EXPECT_FALSE(fs::exists(tmp / "none.stl"));
}

// ------------------------------------------------------------------------ level sets

TEST(VdbMesh, ChestMeshHasNoZeroAreaTriangleAndStaysClosed) {
  // The chest CT at -500 HU: volumeToMesh puts some vertices at one position (values exactly
  // at tau). Truth by brute force: no two vertices at one position, every triangle of
  // positive area as float32 (what STL stores), every edge in exactly two triangles.
  const engine::Volume v =
      io::load_volume(std::string(ISOTOUCH_TEST_DATA) + "/ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd");
  const Mesh m = extract_mesh(v, Isosurface{-500.0, InsideIs::kAbove});
  EXPECT_GT(m.dropped_triangles, 0u) << "this volume has coincident vertices to weld";
  std::set<std::array<double, 3>> seen(m.vertices.begin(), m.vertices.end());
  EXPECT_EQ(seen.size(), m.vertices.size()) << "two vertices at one position";
  std::size_t zero = 0;
  for (const auto& t : m.triangles) {
    std::array<std::array<float, 3>, 3> p{};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) p[k][a] = float(m.vertices[t[k]][a]);
    const double u[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const double w[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    const double c[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    zero += c[0] == 0 && c[1] == 0 && c[2] == 0;
  }
  EXPECT_EQ(zero, 0u) << "zero-area triangles";
  const MeshStats st = mesh_stats(m);
  EXPECT_TRUE(st.closed()) << st.boundary_edges << " boundary, " << st.nonmanifold_edges << " non-manifold edges";
  EXPECT_EQ(st.degenerate_triangles, 0u);
}

TEST(VdbIo, OpenVdbLevelSetSphereLoadsAsInsideBelowInAlignedBricks) {
  TempDir tmp;
  const std::string path = tmp / "ls.vdb";
  write_test_vdb(path, TestVdb::kLevelSetSphere);  // r = 20 mm, voxel 1 mm, centre 0, half-width 3
  const LoadedVdb l = load_vdb(path);
  ASSERT_TRUE(l.suggested.has_value());
  EXPECT_EQ(l.suggested->tau, 0.0);
  EXPECT_EQ(l.suggested->inside, InsideIs::kBelow);
  EXPECT_EQ(l.grid_class, "level set");
  EXPECT_FALSE(l.written_by_isotouch);
  const engine::Volume& v = l.volume;
  // Bricks line up with the VDB leaves: origin and far end on multiples of 8 voxels.
  for (int a = 0; a < 3; ++a) {
    const double o = (&v.grid.origin_m.x)[a] / (&v.grid.spacing_m.x)[a];
    EXPECT_NEAR(o, 8.0 * std::round(o / 8.0), 1e-6) << "axis " << a;
    EXPECT_EQ(v.grid.dims[std::size_t(a)] % 8, 0) << "axis " << a;
    EXPECT_NEAR((&v.grid.spacing_m.x)[a], 1e-3, 1e-10);  // OpenVDB's float voxel size
    // The band (|d| < 3 voxels around r = 20: voxels -22..22) plus the 1-voxel margin fits.
    EXPECT_LE(o, -23.0 + 1e-9);
    EXPECT_GE(o + v.grid.dims[std::size_t(a)] - 1, 23.0 - 1e-9);
  }
  // Values: the signed distance near the surface, -background deep inside, +background outside.
  std::size_t near_bad = 0, inside_bad = 0, outside_bad = 0;
  for (int z = 0; z < v.grid.dims[2]; ++z)
    for (int y = 0; y < v.grid.dims[1]; ++y)
      for (int x = 0; x < v.grid.dims[0]; ++x) {
        const auto p = v.grid.to_world({double(x), double(y), double(z)});
        const double d = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z) - 0.02;
        const float val = v.voxels[v.grid.index(x, y, z)];
        if (std::abs(d) < 2e-3) near_bad += std::abs(val - d) > 0.5e-3;
        if (d < -4e-3) inside_bad += !(val < 0);
        if (d > 4e-3) outside_bad += val != l.background;
      }
  EXPECT_EQ(near_bad, 0u);
  EXPECT_EQ(inside_bad, 0u);
  EXPECT_EQ(outside_bad, 0u);
  // Its mesh is the sphere.
  const Mesh m = extract_mesh(v, *l.suggested);
  EXPECT_TRUE(closed(m.triangles));
  const Figures f = figures(m.vertices, m.triangles);
  EXPECT_NEAR(f.area / (4 * std::numbers::pi * 0.02 * 0.02), 1.0, 0.01);
  EXPECT_GT(f.volume, 0.0);
}

// ------------------------------------------------------------------------ bad input

TEST(VdbIo, BadInputGivesClearErrors) {
  TempDir tmp;
  expect_error([&] { load_vdb(tmp / "missing.vdb"); }, {"missing.vdb", "no such file"});
  {
    std::ofstream(tmp / "text.vdb") << "this is not a vdb file\n";
    expect_error([&] { load_vdb(tmp / "text.vdb"); }, {"text.vdb", "not a readable OpenVDB file"});
  }
  write_test_vdb(tmp / "ints.vdb", TestVdb::kNoFloatGrid);
  expect_error([&] { load_vdb(tmp / "ints.vdb"); }, {"ints.vdb", "no float grid", "'labels' (int32)", "'velocity'"});
  expect_error([&] { load_vdb(tmp / "ints.vdb", "labels"); }, {"ints.vdb", "'labels'", "not float"});
  write_test_vdb(tmp / "empty.vdb", TestVdb::kEmptyFloatGrid);
  expect_error([&] { load_vdb(tmp / "empty.vdb"); }, {"empty.vdb", "grid 'empty'", "no active voxel"});
  write_test_vdb(tmp / "huge.vdb", TestVdb::kHugeBox);
  expect_error([&] { load_vdb(tmp / "huge.vdb"); }, {"huge.vdb", "grid 'far'", "above the limit"});
  // A crafted box 2^31 x 2^17 x 2^16: int32 extents wrap and their product is 0 mod 2^64,
  // which once allocated nothing and let copyToDense write past it.
  write_test_vdb(tmp / "wrap.vdb", TestVdb::kWrappingBox);
  expect_error([&] { load_vdb(tmp / "wrap.vdb"); }, {"wrap.vdb", "grid 'wrap'", "2147483648 x 131072 x 65536", "above the limit"});
  expect_error([&] { load_vdb(tmp / "wrap.vdb", "", ~std::uint64_t(0)); }, {"wrap.vdb", "2147483648 x 131072 x 65536"});
  write_test_vdb(tmp / "rot.vdb", TestVdb::kRotated);
  expect_error([&] { load_vdb(tmp / "rot.vdb"); }, {"rot.vdb", "grid 'rotated'", "rotation"});
  write_test_vdb(tmp / "ls.vdb", TestVdb::kLevelSetSphere);
  expect_error([&] { load_vdb(tmp / "ls.vdb", "nope"); }, {"ls.vdb", "no grid named 'nope'", "'sphere' (float)"});
  expect_error([&] { load_vdb(tmp.dir.string()); }, {"not a regular file"});
  // A voxel-count limit of our choosing.
  expect_error([&] { load_vdb(tmp / "ls.vdb", "", 1000); }, {"ls.vdb", "above the limit of 1000 voxels"});
  // Saving into a folder that does not exist; meshing with a bad adaptivity.
  const engine::Volume v = sdf_sphere(8, 1e-3, 2.0, InsideIs::kBelow);
  expect_error([&] { save_vdb(v, tmp / "no/such/folder/x.vdb"); }, {"x.vdb", "does not exist"});
  expect_error([&] { extract_mesh(v, {0.0, InsideIs::kBelow}, 2.0); }, {"adaptivity", "[0, 1]"});
}

// The limits every volume format meets (io::check_volume_limits), on a .vdb written by
// save_vdb: its metadata carry the exact spacing, origin and direction.
TEST(VdbIo, LimitsOfEveryVolumeApply) {
  TempDir tmp;
  engine::Volume v = sdf_sphere(16, 1e-3, 5.0, InsideIs::kBelow);
  engine::Volume wide = v;
  wide.grid.spacing_m = {1.0, 1e-3, 1e-3};  // 15 m along x
  save_vdb(wide, tmp / "wide.vdb");
  expect_error([&] { load_vdb(tmp / "wide.vdb"); },
               {"wide.vdb", "grid 'volume'", "field 'transform scale (voxel size)' along axis 0 is 1000 mm", "15 m",
                "the limit is 10 m"});
  engine::Volume far = v;
  far.grid.origin_m = {0, 2000.0, 0};
  save_vdb(far, tmp / "far.vdb");
  expect_error([&] { load_vdb(tmp / "far.vdb"); },
               {"far.vdb", "field 'transform translation (origin)' along axis 1 is 2e+06 mm", "within 1000 m"});
  engine::Volume nan_dir = v;
  nan_dir.direction[4] = std::nan("");
  save_vdb(nan_dir, tmp / "nandir.vdb");
  expect_error([&] { load_vdb(tmp / "nandir.vdb"); },
               {"nandir.vdb", "field 'isotouch_direction'", "nan", "not orthonormal"});
  engine::Volume scaled = v;
  scaled.direction = {2, 0, 0, 0, 1, 0, 0, 0, 1};
  save_vdb(scaled, tmp / "scaled.vdb");
  expect_error([&] { load_vdb(tmp / "scaled.vdb"); }, {"scaled.vdb", "isotouch_direction", "not orthonormal"});
  // What passes them still loads, bit for bit.
  save_vdb(v, tmp / "ok.vdb");
  expect_identical(load_vdb(tmp / "ok.vdb").volume, v);
}

// A file of a few kB whose tiles make an 8 GiB dense volume: refused by the memory check
// before anything is allocated, in a child whose address space may grow by 4 GiB only.
TEST(VdbIo, TileBoxBeyondTheMemoryIsRefusedBeforeAllocating) {
  TempDir tmp;
  write_test_vdb(tmp / "tiles.vdb", TestVdb::kTileBox);
  EXPECT_LT(fs::file_size(tmp / "tiles.vdb"), 64u << 10);
  const std::string m = test::message_under_memory_limit(test::address_space_bytes() + (4ull << 30),
                                                        [&] { (void)load_vdb(tmp / "tiles.vdb"); });
  for (const char* part : {"tiles.vdb", "grid 'tiles'", "1936 x 1040 x 1040 voxels of float need 7987 MiB",
                           "MiB of memory this process may use"})
    EXPECT_NE(m.find(part), std::string::npos) << "message '" << m << "' lacks '" << part << "'";
}

// ------------------------------------------------------------------------ isotouch export

TEST(VdbExportCmd, HeadCtToVdbAndMeshesThenVdbToStl) {
  TempDir tmp;
  ExportOptions o;
  o.volume = std::string(ISOTOUCH_TEST_DATA) + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
  o.iso = 1150;
  o.inside = "above";
  o.vdb = tmp / "head.vdb";
  o.stl = tmp / "head.stl";
  o.obj = tmp / "head.obj";
  o.ply = tmp / "head.ply";
  std::ostringstream out, err;
  ASSERT_EQ(run_export(o, out, err), 0) << out.str() << err.str();
  std::printf("%s", out.str().c_str());
  EXPECT_NE(out.str().find("closed      yes"), std::string::npos) << out.str();
  const ReadMesh stl = read_stl(o.stl);
  EXPECT_GT(stl.t.size(), 1000u);
  // In millimetres: the skull fills most of the CT's box, which its header gives (physical
  // frame, LPS: origin + D (spacing * index)), one voxel of margin on each side.
  const engine::Volume head = io::load_any_volume(o.volume);
  const Figures g = figures(stl.v, stl.t);
  const double sp[3] = {head.grid.spacing_m.x, head.grid.spacing_m.y, head.grid.spacing_m.z};
  for (int a = 0; a < 3; ++a) {
    double lo = 1e300, hi = -1e300;
    for (int corner = 0; corner < 8; ++corner) {  // index -1 or dims on each axis: a voxel beyond the end voxels
      double p = (&head.grid.origin_m.x)[a];
      for (int j = 0; j < 3; ++j)
        p += head.direction[std::size_t(3 * a + j)] * ((corner >> j & 1) ? head.grid.dims[j] : -1) * sp[j];
      lo = std::min(lo, p * 1e3), hi = std::max(hi, p * 1e3);
    }
    SCOPED_TRACE("axis " + std::to_string(a) + ": box [" + std::to_string(lo) + ", " + std::to_string(hi) + "] mm");
    EXPECT_GE(g.lo[a], lo);
    EXPECT_LE(g.hi[a], hi);
    EXPECT_GT(g.hi[a] - g.lo[a], 0.5 * (hi - lo)) << "the mesh spans under half the box: not in mm?";
  }
  EXPECT_NE(out.str().find("mesh        " + std::to_string(stl.t.size()) + " triangles"), std::string::npos);
  EXPECT_TRUE(closed(read_ply(o.ply).t));
  EXPECT_GT(figures(read_obj(o.obj).v, read_obj(o.obj).t).volume, 0.0);
  // The .vdb again as input: its isosurface comes from its metadata; the same mesh.
  ExportOptions o2;
  o2.volume = o.vdb;
  o2.stl = tmp / "again.stl";
  std::ostringstream out2, err2;
  ASSERT_EQ(run_export(o2, out2, err2), 0) << out2.str() << err2.str();
  EXPECT_NE(out2.str().find("tau 1150, inside above (.vdb metadata)"), std::string::npos) << out2.str();
  EXPECT_EQ(read_stl(o2.stl).t.size(), stl.t.size());
}

TEST(VdbExportCmd, LevelSetVdbToStlNeedsNoIsovalue) {
  TempDir tmp;
  write_test_vdb(tmp / "ls.vdb", TestVdb::kLevelSetSphere);
  ExportOptions o;
  o.volume = tmp / "ls.vdb";
  o.stl = tmp / "ls.stl";
  std::ostringstream out, err;
  ASSERT_EQ(run_export(o, out, err), 0) << out.str() << err.str();
  EXPECT_NE(out.str().find("tau 0, inside below (level set)"), std::string::npos) << out.str();
  EXPECT_NE(out.str().find("closed      yes"), std::string::npos) << out.str();
}

TEST(VdbExportCmd, BadUsageAndBadInput) {
  TempDir tmp;
  const std::string head = std::string(ISOTOUCH_TEST_DATA) + "/ct-head-headsq/headsq_64x64x93_int16.mhd";
  auto run = [](const ExportOptions& o, std::string& err_text) {
    std::ostringstream out, err;
    const int rc = run_export(o, out, err);
    err_text = err.str();
    return rc;
  };
  std::string e;
  ExportOptions none;
  none.stl = tmp / "x.stl";
  EXPECT_EQ(run(none, e), 2);
  EXPECT_NE(e.find("VOLUME file or --scene"), std::string::npos) << e;
  ExportOptions no_out;
  no_out.volume = head;
  EXPECT_EQ(run(no_out, e), 2);
  EXPECT_NE(e.find("nothing to write"), std::string::npos) << e;
  ExportOptions no_iso;
  no_iso.volume = head;
  no_iso.stl = tmp / "x.stl";
  // Without --iso the volume's own isovalue (engine::choose_isovalue) is taken.
  EXPECT_EQ(run(no_iso, e), 0) << e;
  EXPECT_TRUE(fs::exists(tmp / "x.stl"));
  fs::remove(tmp / "x.stl");
  ExportOptions bad_inside = no_iso;
  bad_inside.iso = 1150;
  bad_inside.inside = "sideways";
  EXPECT_EQ(run(bad_inside, e), 2);
  EXPECT_NE(e.find("'sideways'"), std::string::npos) << e;
  ExportOptions no_surface = no_iso;
  no_surface.iso = 1e9;
  no_surface.inside = "above";
  EXPECT_EQ(run(no_surface, e), 2);
  EXPECT_NE(e.find("does not cross"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(tmp / "x.stl"));
  ExportOptions missing;
  missing.volume = tmp / "missing.vdb";
  missing.vdb = tmp / "out.vdb";
  expect_error([&] { run(missing, e); }, {"missing.vdb", "no such file"});
}

}  // namespace
}  // namespace isotouch::run
