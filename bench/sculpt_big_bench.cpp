#include "isotouch/bench/sculpt_big_bench.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "isotouch/bench/bench_engine.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::bench {

namespace fs = std::filesystem;

namespace {
/// Trilinear weights of output index i on an axis of `n_out` samples over `n_in` inputs:
/// the lower input index and the fraction toward the next one.
struct AxisMap {
  std::vector<int> i0;
  std::vector<float> f;
};
AxisMap axis_map(int n_in, int n_out) {
  AxisMap m;
  for (int i = 0; i < n_out; ++i) {
    const double x = n_out == 1 ? 0.0 : double(i) * double(n_in - 1) / double(n_out - 1);
    const int lo = std::min(int(std::floor(x)), std::max(n_in - 2, 0));
    m.i0.push_back(lo);
    m.f.push_back(n_in == 1 ? 0.f : float(x - lo));
  }
  return m;
}

std::int16_t to_int16(double v) {
  const double r = std::nearbyint(std::clamp(v, -32768.0, 32767.0));
  return std::int16_t(r);
}
}  // namespace

std::vector<std::int16_t> resample_int16(const engine::Volume& v, const std::array<int, 3>& dims) {
  const auto& n = v.grid.dims;
  if (dims[0] < 1 || dims[1] < 1 || dims[2] < 1 || v.voxels.empty())
    throw std::invalid_argument("resample: dims " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) + " x " +
                                std::to_string(dims[2]) + " of a volume of " + std::to_string(v.voxels.size()) +
                                " voxels");
  const AxisMap mx = axis_map(n[0], dims[0]), my = axis_map(n[1], dims[1]), mz = axis_map(n[2], dims[2]);
  auto at = [&](int x, int y, int z) {
    x = std::min(x, n[0] - 1), y = std::min(y, n[1] - 1), z = std::min(z, n[2] - 1);
    return double(v.voxels[(std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(x)]);
  };
  const std::size_t count = std::size_t(dims[0]) * std::size_t(dims[1]) * std::size_t(dims[2]);
  std::vector<std::int16_t> out(count);
  std::size_t k = 0;
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x, ++k) {
        const int x0 = mx.i0[std::size_t(x)], y0 = my.i0[std::size_t(y)], z0 = mz.i0[std::size_t(z)];
        const double fx = mx.f[std::size_t(x)], fy = my.f[std::size_t(y)], fz = mz.f[std::size_t(z)];
        auto row = [&](int yy, int zz) { return at(x0, yy, zz) + fx * (at(x0 + 1, yy, zz) - at(x0, yy, zz)); };
        auto plane = [&](int zz) { return row(y0, zz) + fy * (row(y0 + 1, zz) - row(y0, zz)); };
        out[k] = to_int16(plane(z0) + fz * (plane(z0 + 1) - plane(z0)));
      }
  return out;
}

void write_mhd_int16(const std::string& mhd_path, const std::vector<std::int16_t>& voxels,
                     const std::array<int, 3>& dims, const std::array<double, 3>& spacing_m,
                     const std::array<double, 3>& origin_m, const std::array<double, 9>& direction) {
  const fs::path mhd(mhd_path);
  const fs::path raw = fs::path(mhd).replace_extension(".raw");
  {
    std::ofstream r(raw, std::ios::binary);
    r.write(reinterpret_cast<const char*>(voxels.data()), std::streamsize(voxels.size() * sizeof(std::int16_t)));
    if (!r) throw std::runtime_error(raw.string() + ": could not be written");
  }
  std::ofstream h(mhd);
  h << std::setprecision(17) << "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n";
  // MetaImage's TransformMatrix lists D by columns (the physical direction of each index axis).
  h << "TransformMatrix =";
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) h << ' ' << direction[std::size_t(3 * r + c)];
  h << "\nOffset = " << origin_m[0] * 1e3 << ' ' << origin_m[1] * 1e3 << ' ' << origin_m[2] * 1e3
    << "\nElementSpacing = " << spacing_m[0] * 1e3 << ' ' << spacing_m[1] * 1e3 << ' ' << spacing_m[2] * 1e3
    << "\nDimSize = " << dims[0] << ' ' << dims[1] << ' ' << dims[2]
    << "\nElementType = MET_SHORT\nElementDataFile = " << raw.filename().string() << "\n";
  if (!h) throw std::runtime_error(mhd.string() + ": could not be written");
}

std::map<std::string, StatLine> parse_sculpt_stats(const std::string& text, std::string* memory) {
  std::map<std::string, StatLine> out;
  std::istringstream in(text);
  std::string line;
  const std::string tag = "stats    ";
  while (std::getline(in, line)) {
    if (line.rfind(tag, 0) != 0) continue;
    std::string body = line.substr(tag.size());
    body.erase(0, body.find_first_not_of(' '));
    if (body.rfind("memory: ", 0) == 0) {
      if (memory) *memory = body.substr(8);
      continue;
    }
    const auto colon = body.rfind(": ");
    if (colon == std::string::npos) continue;
    const std::string what = body.substr(0, colon), rest = body.substr(colon + 2);
    StatLine s{0, kNaN, kNaN};
    if (std::sscanf(rest.c_str(), "n %lf, median %lf ms, p95 %lf ms", &s.n, &s.median, &s.p95) == 3 || rest == "none")
      out[what] = s;
  }
  return out;
}

ServoLine parse_sculpt_servo(const std::string& text) {
  std::istringstream in(text);
  std::string line;
  ServoLine s;
  while (std::getline(in, line)) {
    long t = 0, m = 0;
    if (std::sscanf(line.c_str(), "stats    servo %ld ticks, %ld missed deadlines", &t, &m) == 2) s = {t, m};
  }
  return s;
}

ChildRun run_sculpt_bench(const std::string& exe, const std::vector<std::string>& args, int width,
                          const std::string& device) {
  // Its figures go to stderr: read with stdout.
  std::vector<std::string> argv = {"/bin/sh", "-c", "exec \"$0\" \"$@\" 2>&1"};
  if (std::getenv("DISPLAY") == nullptr || *std::getenv("DISPLAY") == 0)
    argv.insert(argv.end(), {"xvfb-run", "-a", "-s", "-screen 0 1280x1024x24"});
  argv.push_back(!exe.empty() ? exe : (fs::read_symlink("/proc/self/exe").parent_path() / "isotouch-sculpt").string());
  argv.insert(argv.end(), args.begin(), args.end());
  // One round of the script (--bench-ticks 0: no servo-alone phase): the callers gather
  // their own ticks over runs.
  argv.insert(argv.end(), {"--bench", "--bench-ticks", "0", "--size", std::to_string(width), "--render-scale", "1"});
  if (!device.empty()) argv.insert(argv.end(), {"--device", device});
  return run_child_exec(argv);
}

namespace {
std::string load_average() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c + " (1, 5, 15 min) on " + std::to_string(::sysconf(_SC_NPROCESSORS_ONLN)) + " CPUs";
}

/// A path as given, or under the source folder where it is not found from here.
std::string resolve_data(const std::string& rel) {
  if (fs::exists(rel)) return rel;
  return (fs::path(ISOTOUCH_SOURCE_DIR) / rel).string();
}

std::string window_text(const SculptBigOptions& o) {
  return std::to_string(o.width) + "x" + std::to_string(o.width * 3 / 4) + ", render scale 1";
}


/// The made volume: NX x NY x NZ int16 over the source's box, written into `dir`.
std::string make_volume(const engine::Volume& src, const SculptBigOptions& o, int nz, const fs::path& dir,
                        std::ostream& progress) {
  const std::array<int, 3> dims{o.xy[0], o.xy[1], nz};
  std::array<double, 3> sp{}, org{src.grid.origin_m.x, src.grid.origin_m.y, src.grid.origin_m.z};
  const double s_in[3] = {src.grid.spacing_m.x, src.grid.spacing_m.y, src.grid.spacing_m.z};
  for (int a = 0; a < 3; ++a)
    sp[std::size_t(a)] = dims[std::size_t(a)] == 1 ? s_in[a]
                                                   : s_in[a] * double(src.grid.dims[std::size_t(a)] - 1) /
                                                         double(dims[std::size_t(a)] - 1);
  const fs::path mhd = dir / ("sculpt_big_" + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                              std::to_string(nz) + "_int16.mhd");
  progress << "[bench sculpt-big] resampling to " << mhd.filename().string() << "\n" << std::flush;
  write_mhd_int16(mhd.string(), resample_int16(src, dims), dims, sp, org, src.direction);
  return mhd.string();
}

/// isotouch-sculpt INPUT --bench. `input`: a scene, or a volume and its isovalue options.
ChildRun run_sculpt(const SculptBigOptions& o, const std::vector<std::string>& input) {
  return run_sculpt_bench(o.sculpt_exe, input, o.width, o.device);
}

std::string ms(double x) {
  if (!std::isfinite(x)) return "n/a";
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << x;
  return s.str();
}

/// The report of one run: its figures and the verdicts against the targets.
bool report_run(const std::string& name, const ChildRun& r, std::ostream& out) {
  std::string memory;
  const auto st = parse_sculpt_stats(r.out, &memory);
  auto get = [&](const std::string& what) {
    const auto it = st.find(what);
    return it == st.end() ? StatLine{0, kNaN, kNaN} : it->second;
  };
  const StatLine whole = get("frames drawn whole (first, camera or style changed)");
  const StatLine reused = get("frames reusing the last picture (only the probe and the edits drawn again)");
  const StatLine all = get("frame time"), e2p = get("edit-to-pixels (submit to the first frame showing it)");
  const StatLine march = get("march pass (GPU timestamps)");
  out << "\n## " << name << "\n\n";
  if (!r.started || r.exit_code != 0)
    out << "isotouch-sculpt did not complete: " << (r.started ? "exit code " + std::to_string(r.exit_code) : r.error)
        << (r.signal ? ", signal " + std::to_string(r.signal) : "") << "\n";
  out << "| figure | n | median ms | p95 ms |\n|---|---|---|---|\n";
  for (const auto& [what, s] : {std::pair{"frames drawn whole", whole}, {"sculpting frames (reusing the picture)", reused},
                                {"all frames", all}, {"march pass of every frame (GPU)", march},
                                {"edit-to-pixels", e2p}})
    out << "| " << what << " | " << s.n << " | " << ms(s.median) << " | " << ms(s.p95) << " |\n";
  out << "\nmemory: " << (memory.empty() ? "not printed" : memory) << "; peak resident set of the child and its descendants (xvfb's too) "
      << r.peak_rss_bytes / (1024 * 1024) << " MiB (wait4), wall " << ms(r.wall_ms / 1e3) << " s\n";
  for (const Verdict& v : {verdict_at_most("frames drawn whole: median ms", whole.median, 33, 1, "no such frames"),
                           verdict_at_most("frames drawn whole: p95 ms", whole.p95, 50, 1, "no such frames"),
                           verdict_at_most("edit-to-pixels: median ms", e2p.median, 100, 1, "no edit shown")})
    out << "verdict: " << v.text << "\n";
  return r.started && r.exit_code == 0 && !st.empty();
}
}  // namespace

int run_bench_sculpt_big(const SculptBigOptions& o, std::ostream& out, std::ostream& progress) {
  const std::string src_path = resolve_data(o.source);
  out << "# bench sculpt-big\n\nload average before: " << load_average() << "\nsource: " << src_path << "\n";
  fs::path dir = o.keep_dir;
  bool remove_dir = false;
  if (dir.empty()) {
    std::string tmpl = (fs::temp_directory_path() / "isotouch-sculpt-big-XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr) {
      out << "bench sculpt-big: could not make a temporary folder from " << tmpl << "\n";
      return 1;
    }
    dir = tmpl;
    remove_dir = true;
  }
  fs::create_directories(dir);
  bool ok = true;
  try {
    progress << "[bench sculpt-big] loading " << src_path << "\n" << std::flush;
    const engine::Volume src = io::load_volume(src_path);
    for (int nz : o.slices) {
      const std::string vol = make_volume(src, o, nz, dir, progress);
      const std::uint64_t voxels = std::uint64_t(o.xy[0]) * std::uint64_t(o.xy[1]) * std::uint64_t(nz);
      progress << "[bench sculpt-big] isotouch-sculpt --bench on " << vol << "\n" << std::flush;
      std::ostringstream iso;
      iso << std::setprecision(17) << o.iso;
      const ChildRun r = run_sculpt(o, {vol, "--iso", iso.str(), "--inside", "above"});
      progress << r.out;
      ok = report_run(std::to_string(o.xy[0]) + " x " + std::to_string(o.xy[1]) + " x " + std::to_string(nz) +
                          " int16 (" + std::to_string(voxels) + " voxels: " +
                          (voxels > (std::uint64_t(1) << 27) ? "past" : "within") +
                          " 2^27, one single-float texel binding on lavapipe) at " + window_text(o),
                      r, out) && ok;
    }
    if (!o.reference.empty()) {  // the shipped scene, in the same run: what the load does to it
      const std::string scene = resolve_data(o.reference);
      progress << "[bench sculpt-big] isotouch-sculpt --bench on " << scene << "\n" << std::flush;
      const ChildRun r = run_sculpt(o, {scene});
      progress << r.out;
      ok = report_run("reference: " + scene + " at " + window_text(o), r, out) && ok;
    }
  } catch (const std::exception& e) {
    out << "bench sculpt-big: " << e.what() << "\n";
    ok = false;
  }
  if (remove_dir) fs::remove_all(dir);
  out << "\nload average after: " << load_average() << "\n";
  return ok ? 0 : 1;
}

}  // namespace isotouch::bench
