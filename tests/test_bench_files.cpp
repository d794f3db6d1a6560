// The conclusion lines of `bench table1` (HRI/Avila, the tool ticks) are computed from the
// measured rows, and the
// gnuplot helper keeps a plots script that can be re-run (final PNG names, no enhanced
// text), writing the plots whole or not at all.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "isotouch/bench/bench_serve.h"
#include "isotouch/bench/sculpt_big_bench.h"
#include "isotouch/bench/sculpt_device_bench.h"
#include "isotouch/bench/servo_bench.h"
#include "isotouch/bench/tool_bench.h"
#include "isotouch/io/files.h"
#include "isotouch/io/volume_io.h"

using namespace isotouch::bench;
using namespace isotouch::io;
namespace fs = std::filesystem;

TEST(Table1Verdict, CountsTheScenesWhereHriIsNoSlowerThanAvila) {
  std::vector<Table1Row> rows = {{"sphere", 0.060, 0.070, 0.5, 0.065},
                                 {"knot", 0.070, 0.080, 0.5, 0.070},   // equal: no slower
                                 {"head", 0.080, 0.060, 0.5, 0.070},   // slower: ratio 1.14
                                 {"chest", 0.050, 0.050, 0.5, 0.060}};
  EXPECT_EQ(table1_verdict(rows),
            "HRI/Avila <= 1 on 3 of 4 scenes (worst: head 1.14); paper variant (Figure 2 as printed): 2 of 4");
  rows[2].hri_us = 0.069;
  EXPECT_EQ(table1_verdict(rows).rfind("HRI/Avila <= 1 on 4 of 4 scenes (worst: knot 1.00)", 0), 0u)
      << table1_verdict(rows);
  rows[0].avila_us = 0;  // a failed measurement never counts as met
  rows[1].hri_us = std::nan("");
  EXPECT_EQ(table1_verdict(rows).rfind("HRI/Avila <= 1 on 2 of 4 scenes", 0), 0u) << table1_verdict(rows);
}

// The tool lines' verdict: every tool of every scene must have p99 <= 50 us and a median
// within 20 x its scene's point; the worst of each is named; a missing or failed
// measurement never counts as met.
TEST(Table1Verdict, ToolTicksMeetP99AndMedianRatioOrFail) {
  auto tool = [](double rv, double median, double p99) {
    TickSpread t;
    t.radius_voxels = rv;
    t.median_us = median;
    t.p99_us = p99;
    t.ticks = 1000;
    return t;
  };
  ToolTickRow a{"head", tool(0, 0.02, 0.2), {tool(1, 0.1, 10), tool(3, 0.3, 49.9), tool(10, 0.4, 3)}, 20};
  ToolTickRow b{"chest", tool(0, 0.02, 0.2), {tool(1, 0.1, 12), tool(3, 0.4, 20)}, 20};
  std::vector<ToolTickRow> rows = {a, b};
  EXPECT_EQ(tool_tick_verdict(rows),
            "tool ticks: p99 <= 50 us on 5 of 5, median <= 20 x the point's on 5 of 5 (worst p99: head r = 3 voxels "
            "49.90 us; worst median ratio: head r = 10 voxels 20.0 x): PASS");
  rows[1].tools[1].p99_us = 50.5;  // one p99 over the target
  EXPECT_EQ(tool_tick_verdict(rows).rfind("tool ticks: p99 <= 50 us on 4 of 5, median <= 20 x the point's on 5 of 5 "
                                          "(worst p99: chest r = 3 voxels 50.50 us",
                                          0),
            0u)
      << tool_tick_verdict(rows);
  EXPECT_NE(tool_tick_verdict(rows).find(": FAIL"), std::string::npos);
  rows[1].tools[1].p99_us = 20;
  rows[0].tools[2].median_us = 0.41;  // 20.5 x the point
  EXPECT_NE(tool_tick_verdict(rows).find("median <= 20 x the point's on 4 of 5"), std::string::npos) << tool_tick_verdict(rows);
  EXPECT_NE(tool_tick_verdict(rows).find(": FAIL"), std::string::npos);
  rows[0].tools[2].median_us = 0.4;
  rows[1].point.median_us = std::nan("");  // a failed measurement: its tools fail both
  EXPECT_NE(tool_tick_verdict(rows).find("p99 <= 50 us on 3 of 5, median <= 20 x the point's on 3 of 5"), std::string::npos)
      << tool_tick_verdict(rows);
  EXPECT_EQ(tool_tick_verdict({}), "tool ticks: p99 <= 50 us on 0 of 0, median <= 20 x the point's on 0 of 0: FAIL");
}

namespace {
std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}
bool have_gnuplot() { return run_program("gnuplot", "--version") == 0; }
}  // namespace

TEST(Gnuplot, SavedScriptNamesTheFinalPngsAndCanBeRunAgain) {
  const fs::path dir = fs::temp_directory_path() / ("isotouch-gp-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string data = (dir / "d.csv").string();
  { std::ofstream(data) << "t,f\n0,1\n1,2\n2,1.5\n"; }
  const std::string png = (dir / "force_depth.png").string();
  const std::string gp = (dir / "plots.gp").string();
  // What run_job writes: the temp name of the PNG, a title with underscores.
  const std::string script = "set datafile separator ','\nset terminal pngcairo size 300,200\nset output " +
                             gnuplot_quote(temp_name(png)) + "\nset title " + gnuplot_quote("max_force_step_n") +
                             "\nplot " + gnuplot_quote(data) + " every ::1 using 1:2 with lines title 'f_n'\n";
  const std::string why = draw_with_gnuplot(gp, script, {png});

  const std::string saved = slurp(gp);
  EXPECT_NE(saved.find("set output " + gnuplot_quote(png) + "\n"), std::string::npos) << saved;
  EXPECT_EQ(saved.find(".tmp-"), std::string::npos) << "the saved script names a temp file:\n" << saved;
  EXPECT_NE(saved.find("set terminal pngcairo size 300,200\nset termoption noenhanced\n"), std::string::npos)
      << "underscores in titles would become subscripts:\n" << saved;
  EXPECT_FALSE(fs::exists(temp_name(png)));
  EXPECT_FALSE(fs::exists(temp_name(gp) + "-run")) << "the run copy was left behind";
  if (!have_gnuplot()) {
    fs::remove_all(dir);
    GTEST_SKIP() << "gnuplot is not installed: the script text is checked, not run (" << why << ")";
  }
  ASSERT_EQ(why, "");
  ASSERT_TRUE(fs::exists(png));
  // Re-run the saved script as a user would: it writes the final PNG again.
  fs::remove(png);
  EXPECT_EQ(run_program("gnuplot", gp), 0);
  EXPECT_TRUE(fs::exists(png) && fs::file_size(png) > 0) << "re-running plots.gp wrote no " << png;

  // A script that fails: no PNG appears, no temp file stays.
  fs::remove(png);
  EXPECT_NE(draw_with_gnuplot(gp, script + "this is not gnuplot\n", {png}), "");
  EXPECT_FALSE(fs::exists(png));
  EXPECT_FALSE(fs::exists(temp_name(png)));
  fs::remove_all(dir);
}

TEST(BenchServe, VerdictsFollowTheFiguresAtTheirBounds) {
  BenchServePhase alone, traffic;
  alone.ticks = traffic.ticks = 10000;
  alone.missed = 4;  // limit 4 + 3 sqrt(4) = 10
  traffic.answered = 99;
  traffic.poses = 100;
  alone.answered = 989;
  alone.poses = 1000;
  traffic.p99_us = 1000;
  traffic.missed = 10;
  auto v = bench_serve_verdicts(alone, traffic);
  ASSERT_EQ(v.size(), 4u);
  EXPECT_NE(v[0].find("= 1000.0 us: target <= 1000 us met"), std::string::npos) << v[0];
  EXPECT_NE(v[1].find("alone 989 of 1000 = 98.90 %: target >= 99 % NOT met"), std::string::npos) << v[1];
  EXPECT_NE(v[2].find("with traffic 99 of 100 = 99.00 %: target >= 99 % met"), std::string::npos) << v[2];
  EXPECT_NE(v[3].find("10 <= 4 without + 3 sqrt(4) = 10.0: met"), std::string::npos) << v[3];
  traffic.p99_us = 1000.5;
  traffic.missed = 11;
  traffic.answered = 98;
  v = bench_serve_verdicts(alone, traffic);
  EXPECT_NE(v[0].find("NOT met"), std::string::npos) << v[0];
  EXPECT_NE(v[2].find("NOT met"), std::string::npos) << v[2];
  EXPECT_NE(v[3].find("NOT met"), std::string::npos) << v[3];
  traffic.answered = 0;  // nothing measured is never met
  traffic.p99_us = 0;
  EXPECT_NE(bench_serve_verdicts(alone, traffic)[0].find("none answered"), std::string::npos);
}

// `bench sculpt-big`'s volume: a linear field (which trilinear resampling reproduces
// exactly) resampled onto more voxels over the same box, written as int16 MetaImage and
// read back by the loader the app uses: dims, spacing, origin, a rotated direction and every
// voxel as the field at its new place, rounded; values past int16 clamped.
TEST(SculptBig, ResampledVolumeReadsBackAsTheFieldOverTheSameBox) {
  isotouch::engine::Volume v;
  v.grid.dims = {5, 4, 3};
  v.grid.spacing_m = {2e-3, 3e-3, 5e-3};
  v.grid.origin_m = {0.01, -0.02, 0.03};
  v.direction = {0, -1, 0, 1, 0, 0, 0, 0, 1};  // x index runs along physical +y, y along -x
  auto field = [](double x, double y, double z) { return 100.0 + 30.0 * x - 20.0 * y + 7.0 * z; };  // index units
  for (int z = 0; z < 3; ++z)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 5; ++x) v.voxels.push_back(float(field(x, y, z)));
  v.voxels.back() = 1e6f;  // past int16: clamped to 32767 (only the corner voxel itself)
  const std::array<int, 3> dims{9, 7, 11};
  const std::vector<std::int16_t> out = resample_int16(v, dims);
  ASSERT_EQ(out.size(), 9u * 7u * 11u);
  const fs::path dir = fs::temp_directory_path() / ("isotouch-sculpt-big-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::array<double, 3> sp{2e-3 * 4 / 8, 3e-3 * 3 / 6, 5e-3 * 2 / 10};
  write_mhd_int16((dir / "v.mhd").string(), out, dims, sp, {0.01, -0.02, 0.03}, v.direction);
  const isotouch::engine::Volume back = load_volume((dir / "v.mhd").string());
  fs::remove_all(dir);
  EXPECT_EQ(back.grid.dims, dims);
  EXPECT_NEAR(back.grid.spacing_m.z, 1e-3, 1e-12);
  EXPECT_NEAR(back.grid.origin_m.y, -0.02, 1e-12);
  for (std::size_t i = 0; i < 9; ++i) EXPECT_NEAR(back.direction[i], v.direction[i], 1e-12) << "direction entry " << i;
  std::size_t k = 0, wrong = 0;
  for (int z = 0; z < 11; ++z)
    for (int y = 0; y < 7; ++y)
      for (int x = 0; x < 9; ++x, ++k) {
        const bool corner = x == 8 && y == 6 && z == 10;
        const double want = corner ? 32767.0 : std::nearbyint(field(x * 4.0 / 8, y * 3.0 / 6, z * 2.0 / 10));
        // Voxels whose trilinear weights reach the clamped corner are not the linear field.
        const bool near_corner = x > 6 && y > 4 && z > 5;
        if (!near_corner && std::fabs(double(back.voxels[k]) - want) > 0) ++wrong;
        if (corner) {
          EXPECT_EQ(back.voxels[k], 32767.f);
        }
      }
  EXPECT_EQ(wrong, 0u);
  EXPECT_THROW(resample_int16(v, {0, 4, 4}), std::invalid_argument);
}

// The servo line `bench sculpt-device` reads: ticks and misses, -1 when it is missing.
TEST(SculptDevice, ServoLineIsRead) {
  const std::string text =
      "stats    edit-to-haptics: n 2, median 5.81 ms, p95 10.08 ms, max 10.08 ms\n"
      "stats    servo 55012 ticks, 32 missed deadlines, period error p99 86 us, 0 faults; edits 4 requested\n"
      "verdict: servo missed deadlines while sculpting 32 of 50010 ticks\n";
  const ServoLine s = parse_sculpt_servo(text);
  EXPECT_EQ(s.ticks, 55012);
  EXPECT_EQ(s.missed, 32);
  const ServoLine none = parse_sculpt_servo("stats    frame time: n 3, median 1 ms, p95 1 ms, max 1 ms\n");
  EXPECT_EQ(none.ticks, -1);
  EXPECT_EQ(none.missed, -1);
}

// ref + 3 sqrt(ref), ref scaled to the device's tick count.
TEST(SculptDevice, MissesAgainstTheReference) {
  EXPECT_FALSE(misses_within(11, 20000, 4, 20000));
  EXPECT_TRUE(misses_within(10, 20000, 4, 20000));    // ref 4: at most 4 + 3 * 2 = 10
  EXPECT_TRUE(misses_within(16, 40000, 4, 20000));    // ref 8 at 40,000 ticks: at most 8 + 8.49
  EXPECT_FALSE(misses_within(17, 40000, 4, 20000));
  EXPECT_TRUE(misses_within(0, 20000, 0, 20000));
  EXPECT_FALSE(misses_within(1, 20000, 0, 20000));
  EXPECT_FALSE(misses_within(0, 0, 0, 20000));        // no ticks: not judged a pass
  EXPECT_FALSE(misses_within(0, 19999, 0, 20000));    // fewer than 20,000 ticks on either side
  EXPECT_FALSE(misses_within(0, 20000, 0, 19999));
}

TEST(SculptDevice, RatioVerdict) {
  EXPECT_EQ(ratio_verdict(11.0, 10.0), "device / mouse = 1.10: <= 1.10 PASS");
  EXPECT_EQ(ratio_verdict(11.2, 10.0), "device / mouse = 1.12: <= 1.10 FAIL");
  EXPECT_EQ(ratio_verdict(5.0, 0.0), "device / mouse = n/a: <= 1.10 FAIL");
  EXPECT_EQ(ratio_verdict(NAN, 10.0), "device / mouse = n/a: <= 1.10 FAIL");
}

// The figures `bench sculpt-big` reads from isotouch-sculpt's --bench lines.
TEST(SculptBig, StatLinesAreReadByTheirName) {
  const std::string text =
      "sculpt   sculpt: 512x512x600 voxels\n"
      "stats    frame time: n 86, median 153.14 ms, p95 604.38 ms, max 1035.99 ms\n"
      "stats      frames drawn whole (first, camera or style changed): n 31, median 195.19 ms, p95 745.26 ms, max 1035.99 ms\n"
      "stats    edit-to-pixels (submit to the first frame showing it): none\n"
      "stats    memory: peak resident set 6244 MiB (now 5137 MiB); device memory 773 MiB now\n";
  std::string memory;
  const auto st = parse_sculpt_stats(text, &memory);
  ASSERT_EQ(st.count("frame time"), 1u);
  EXPECT_EQ(st.at("frame time").n, 86);
  EXPECT_DOUBLE_EQ(st.at("frames drawn whole (first, camera or style changed)").median, 195.19);
  EXPECT_DOUBLE_EQ(st.at("frames drawn whole (first, camera or style changed)").p95, 745.26);
  ASSERT_EQ(st.count("edit-to-pixels (submit to the first frame showing it)"), 1u);
  EXPECT_TRUE(std::isnan(st.at("edit-to-pixels (submit to the first frame showing it)").median));
  EXPECT_EQ(memory, "peak resident set 6244 MiB (now 5137 MiB); device memory 773 MiB now");
  EXPECT_EQ(st.size(), 3u);
}
