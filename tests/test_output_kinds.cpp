// Every kind of output isotouch writes (PNG, CSV, JSON, .vdb, STL/OBJ/PLY, recordings,
// gnuplot plots) goes through the one output writer: a character device or FIFO is written
// in place, a symlink is followed, a directory refused; none of them is ever replaced.
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "isotouch/tests/temp_dir.h"

#include "isotouch/io/files.h"
#include "isotouch/io/record.h"
#include "isotouch/run/picture.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_write.h"

namespace fs = std::filesystem;
using isotouch::test::slurp;
using TempDir = isotouch::test::TempDir;
using namespace isotouch;

namespace {



mode_t type_of(const fs::path& p) {
  struct stat st {};
  return ::lstat(p.c_str(), &st) == 0 ? (st.st_mode & S_IFMT) : 0;
}

/// A small volume and its mesh for the writers that need one.
struct Fixtures {
  engine::Volume vol = engine::make_sphere({12, 12, 12}, 0.001, 4.0);
  io::Mesh mesh;
  io::Recording rec;
  Fixtures() {
    mesh.vertices = {{0, 0, 0}, {0.001, 0, 0}, {0, 0.001, 0}, {0, 0, 0.001}};
    mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    rec.scene_path = "/nowhere/scene.json";
    rec.scene_text = "{}";
    rec.rate_hz = 1000;
    rec.volume_crc32 = io::volume_crc32(vol);
    rec.ticks.push_back({0, {0.001, 0.002, 0.003}, false, {0, 0, 0.5}, {0.001, 0.002, 0.0025}, 1});
  }
};

struct Kind {
  std::string name;
  std::function<void(const std::string&)> write;
};

std::vector<Kind> kinds(const Fixtures& f) {
  return {
      {"png", [](const std::string& p) { run::write_png(p, 2, 2, {0xff0000ffu, 0xff00ff00u, 0xffff0000u, 0xffffffffu}); }},
      {"csv", [](const std::string& p) { io::write_file_atomic(p, "t_s,f_n\n0,0\n"); }},
      {"json", [](const std::string& p) { io::write_file_atomic(p, "{\"status\": \"complete\"}\n"); }},
      {"vdb", [&f](const std::string& p) { io::save_vdb(f.vol, p); }},
      {"stl", [&f](const std::string& p) { io::write_stl_binary(f.mesh, p); }},
      {"obj", [&f](const std::string& p) { io::write_obj(f.mesh, p); }},
      {"ply", [&f](const std::string& p) { io::write_ply(f.mesh, p); }},
      {"recording", [&f](const std::string& p) { io::save_recording(p, f.rec); }},
      {"nrrd", [&f](const std::string& p) { io::save_volume_itk(f.vol, p); }},
      {"nii.gz", [&f](const std::string& p) { io::save_volume_itk(f.vol, p); }},
  };
}

}  // namespace

TEST(OutputKinds, EveryKindWritesARegularFileAndThroughASymlink) {
  Fixtures f;
  for (const Kind& k : kinds(f)) {
    SCOPED_TRACE(k.name);
    TempDir d;
    const fs::path plain = d.path / ("out." + k.name);
    k.write(plain.string());
    ASSERT_EQ(type_of(plain), S_IFREG);
    const std::string bytes = slurp(plain);
    EXPECT_FALSE(bytes.empty());
    fs::create_directories(d.path / "real");
    const fs::path target = d.path / "real" / ("file." + k.name), link = d.path / ("link." + k.name);
    std::ofstream(target) << "old";
    fs::create_symlink(target, link);
    k.write(link.string());
    EXPECT_EQ(type_of(link), S_IFLNK) << "the symlink was replaced";
    if (k.name == "vdb") EXPECT_EQ(slurp(target).size(), bytes.size());  // OpenVDB stamps a UUID per file
    else if (k.name == "nii.gz") EXPECT_FALSE(slurp(target).empty());     // gzip stamps the time
    else EXPECT_EQ(slurp(target), bytes) << "the symlink's target holds the new output";
  }
}

TEST(OutputKinds, EveryKindWritesACharacterDeviceInPlace) {
  Fixtures f;
  for (const Kind& k : kinds(f)) {
    SCOPED_TRACE(k.name);
    TempDir d;
    // Named with the kind's extension: the volume writers pick the format by the name.
    const fs::path dev = d.path / ("null." + k.name), link = d.path / ("to-null." + k.name);
    if (::mknod(dev.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0) GTEST_SKIP() << "mknod not permitted here";
    fs::create_symlink(dev, link);
    k.write(dev.string());
    EXPECT_EQ(type_of(dev), S_IFCHR) << "the device node was replaced by a regular file";
    k.write(link.string());
    EXPECT_EQ(type_of(link), S_IFLNK);
    EXPECT_EQ(type_of(dev), S_IFCHR);
  }
}

TEST(OutputKinds, EveryKindWritesAFifoAsAStream) {
  Fixtures f;
  for (const Kind& k : kinds(f)) {
    SCOPED_TRACE(k.name);
    TempDir d;
    const fs::path plain = d.path / ("out." + k.name), fifo = d.path / ("pipe." + k.name);
    k.write(plain.string());
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    auto reader = std::async(std::launch::async, [&] { return slurp(fifo); });
    k.write(fifo.string());
    const std::string streamed = reader.get();
    EXPECT_EQ(type_of(fifo), S_IFIFO);
    if (k.name == "vdb") EXPECT_EQ(streamed.size(), slurp(plain).size());  // OpenVDB stamps a UUID per file
    else if (k.name == "nii.gz") EXPECT_FALSE(streamed.empty());         // gzip stamps the time
    else EXPECT_EQ(streamed, slurp(plain));
  }
}

TEST(OutputKinds, EveryKindRefusesADirectoryNamingIt) {
  Fixtures f;
  for (const Kind& k : kinds(f)) {
    SCOPED_TRACE(k.name);
    TempDir d;
    const fs::path dir = d.path / ("folder." + k.name);
    fs::create_directories(dir);
    try {
      k.write(dir.string());
      ADD_FAILURE() << "a directory must be refused";
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find(dir.string()), std::string::npos) << e.what();
    }
    EXPECT_TRUE(fs::is_directory(dir));
  }
}

TEST(OutputKinds, GnuplotPlotsFollowASymlinkedPng) {
  if (io::run_program("gnuplot", "--version") != 0) GTEST_SKIP() << "gnuplot not installed";
  TempDir d;
  fs::create_directories(d.path / "elsewhere");
  const fs::path png = d.path / "plot.png", target = d.path / "elsewhere" / "plot.png";
  fs::create_symlink(target, png);
  const std::string script = "set terminal pngcairo size 64,48\nset output " +
                             io::gnuplot_quote(io::temp_name(png.string())) + "\nplot x\n";
  EXPECT_EQ(io::draw_with_gnuplot((d.path / "plots.gp").string(), script, {png.string()}), "");
  EXPECT_EQ(type_of(png), S_IFLNK);
  EXPECT_EQ(type_of(target), S_IFREG);
  EXPECT_GT(fs::file_size(target), 0u);
}
