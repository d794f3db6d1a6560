// sculpt_big_bench.h - `isotouch bench sculpt-big`: the sculpting window on a full-resolution
// CT. A shipped scan is resampled to 512 x 512 x 600 int16 voxels (1.6e8: past one
// single-float texel binding, 2^27 on lavapipe) in a temporary folder, never committed;
// `isotouch-sculpt VOLUME --bench` runs on it at 1024 x 768 and render scale 1 (under
// xvfb-run without a display), and again on the same scan at 512 x 512 x 480 (1.26e8 voxels:
// one binding of single floats) and on the shipped chest scene, for comparison in the same
// run. Printed: frames drawn whole, sculpting frames, edit-to-pixels, memory, with verdicts;
// the machine's load before and after.
#pragma once
#include <array>
#include <cstdint>
#include <iosfwd>
#include <map>
#include <string>
#include <vector>

#include "isotouch/bench/bench_engine.h"
#include "isotouch/engine/volume.h"

namespace isotouch::bench {

struct SculptBigOptions {
  std::string source = "data/ct-chest-lungdx-a0001/dicom-5mm";  ///< the scan resampled (512 x 512 x 64)
  std::string reference = "scenes/chest.json";  ///< also run on this scene, for the load's effect (empty: not)
  std::array<int, 2> xy{512, 512};  ///< voxels along x and y
  std::vector<int> slices{600, 480};///< one run per slice count, in this order
  double iso = -500;                ///< isovalue [HU], inside above
  int width = 1024;                 ///< the window's width [pixels]; its height is 3/4 of it
  std::string sculpt_exe;           ///< isotouch-sculpt (default: beside this executable)
  std::string keep_dir;             ///< keep the volumes here (default: a temporary folder, removed)
  std::string device;               ///< Vulkan device (substring), passed on
};

/// `v` resampled trilinearly onto `dims` voxels spanning the same box (the first and last
/// voxel centres stay where they were: spacing (n - 1) s / (dims - 1) per axis; a dims of 1
/// keeps the first voxel), rounded to the nearest int16 and clamped into its range.
/// @throws std::invalid_argument on a dims below 1 or an empty volume.
std::vector<std::int16_t> resample_int16(const engine::Volume& v, const std::array<int, 3>& dims);

/// Writes `voxels` (x fastest) as MetaImage: PATH (.mhd header: MET_SHORT, little endian,
/// the grid's spacing and origin in mm, the direction D) and its .raw beside it.
/// @throws std::runtime_error naming the file that could not be written.
void write_mhd_int16(const std::string& mhd_path, const std::vector<std::int16_t>& voxels,
                     const std::array<int, 3>& dims, const std::array<double, 3>& spacing_m,
                     const std::array<double, 3>& origin_m, const std::array<double, 9>& direction);

/// One figure line of isotouch-sculpt's --bench output ("stats    WHAT: n N, median M ms,
/// p95 P ms, max X ms"): n, median, p95 [ms] (NaN when the line says none or is missing).
struct StatLine {
  double n = 0, median = 0, p95 = 0;
};
/// The stat lines of `text`, by WHAT with its leading spaces removed ("frame time",
/// "frames drawn whole (first, camera or style changed)", ...), and "memory" -> the memory
/// line's text in `memory`.
std::map<std::string, StatLine> parse_sculpt_stats(const std::string& text, std::string* memory = nullptr);

/// The servo line of isotouch-sculpt's --bench output ("stats    servo T ticks, M missed
/// deadlines, ..."): ticks and missed deadlines; both -1 when the line is missing.
struct ServoLine {
  long ticks = -1, missed = -1;
};
ServoLine parse_sculpt_servo(const std::string& text);

/// isotouch-sculpt at `exe` (empty: beside this executable) with `args` (the input first),
/// then --bench --size WIDTH --render-scale 1 and --device DEVICE when given, under xvfb-run
/// when there is no display; its stderr read with its stdout.
ChildRun run_sculpt_bench(const std::string& exe, const std::vector<std::string>& args, int width,
                          const std::string& device);

/// Runs the bench; prints the report to `out`, progress to `progress`.
/// @return 0 when every run completed (whether or not a target was met), 1 otherwise.
int run_bench_sculpt_big(const SculptBigOptions& o, std::ostream& out, std::ostream& progress);

}  // namespace isotouch::bench
