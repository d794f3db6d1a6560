// The playback device: tick k reads the sample recorded at k periods; a trace.csv of a run
// played back through the same renderer reproduces the run's forces; bad traces are refused
// with the file, line and column.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <iomanip>

#include "isotouch/sim/analytic_fields.h"
#include "isotouch/sim/headless.h"
#include "isotouch/servo/hri.h"
#include "isotouch/sim/null_device_io.h"
#include "isotouch/sim/playback_device_io.h"
#include "isotouch/sim/script.h"
#include "isotouch/tests/temp_dir.h"

using namespace isotouch::core;
using namespace isotouch::servo;
using namespace isotouch::sim;

TEST(PlaybackDevice, ReadsTheSampleOfEachTickAndHoldsTheLast) {
  PlaybackDeviceIO d({{0.0, {1, 0, 0}, 0}, {0.002, {2, 0, 0}, 1}, {0.0035, {3, 0, 0}, 0}}, 0.001);
  const double want[] = {1, 1, 2, 2, 3, 3};
  for (double w : want) EXPECT_EQ(d.read_position_m().x, w);
  EXPECT_THROW(PlaybackDeviceIO({}, 0.001), std::invalid_argument);
  EXPECT_THROW(PlaybackDeviceIO({{0.0, {}, 0}, {0.0, {}, 0}}, 0.001), std::invalid_argument);
  NullDeviceIO null({0.1, 0.2, 0.3});
  null.write_force_n({5, 5, 5});
  EXPECT_EQ(null.read_position_m().y, 0.2);
}

TEST(PlaybackDevice, ATraceOfARunReproducesItsForces) {
  // A run: the scripted hand pressing into a sphere (simulated device, fixed rate).
  const SampleField f = sphere_field({0.024, 0.024, 0.024}, 0.015);
  TripleBuffer<SampleField> buf;
  buf.publish(std::make_shared<const SampleField>(f));
  HriParams hp;
  HriRenderer r1(hp);
  ScriptParams sp;
  sp.stroke_length_m = 0.01;
  const TouchScript script = make_touch_script(f, hp, sp);
  Vec3 p0, v0;
  script.at(0, p0, v0);
  SimDevice dev({}, p0);
  const auto trace = run_headless(buf, r1, dev, {}, script, hp.rate_hz);
  // Its trace.csv (HIP in world = device here), at full precision.
  isotouch::test::TempDir dir("playback");
  const std::string csv = (dir.path / "trace.csv").string();
  {
    std::ofstream out(csv);
    out << "t_s,hip_x_m,hip_y_m,hip_z_m,f_x_n\n" << std::setprecision(17);
    for (const TraceRow& t : trace) out << t.t_s << ',' << t.hip_m.x << ',' << t.hip_m.y << ',' << t.hip_m.z << ",0\n";
  }
  PlaybackDeviceIO play(load_trace_hips(csv), 1.0 / hp.rate_hz);
  HriRenderer r2(hp);
  long contact = 0;
  for (const TraceRow& t : trace) {
    const HriTick out = r2.tick(f, play.read_position_m());
    play.write_force_n(out.force_n);
    ASSERT_EQ(out.force_n.x, t.force_n.x) << "t = " << t.t_s;
    ASSERT_EQ(out.force_n.y, t.force_n.y) << "t = " << t.t_s;
    ASSERT_EQ(out.force_n.z, t.force_n.z) << "t = " << t.t_s;
    contact += t.contact;
  }
  EXPECT_GT(contact, 100);  // the run touched the sphere
}

TEST(PlaybackDevice, BadTracesAreRefusedWithFileLineAndColumn) {
  isotouch::test::TempDir dir("playback-bad");
  auto write = [&](const std::string& text) {
    const std::string p = (dir.path / "t.csv").string();
    std::ofstream(p) << text;
    return p;
  };
  auto message = [&](const std::string& text) {
    try {
      load_trace_hips(write(text));
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message("x,y\n1,2\n").find("t.csv:1: not a trace.csv"), std::string::npos);
  EXPECT_NE(message("t_s,hip_x_m,hip_y_m,hip_z_m\n0,1,nan,3\n").find("t.csv:2: column 3 ('nan')"), std::string::npos);
  EXPECT_NE(message("t_s,hip_x_m,hip_y_m,hip_z_m\n0,1,2,3\n0,1,2,3\n").find("t.csv:3: t_s 0"), std::string::npos);
  EXPECT_NE(message("t_s,hip_x_m,hip_y_m,hip_z_m\n").find("no rows"), std::string::npos);
  EXPECT_THROW(load_trace_hips((dir.path / "missing.csv").string()), std::runtime_error);
}
