// Replay (run/replay.h): a scene run with --record replays to identical forces, VHIPs and
// snapshot versions; one HIP moved by one ULP, one edit's radius changed, an absurd HIP or
// another snapshot version differ at that tick; another volume is refused; the scene text the
// recording carries runs wherever the scene file is now.
#include <gtest/gtest.h>
#include <unistd.h>

#include <bit>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "isotouch/io/record.h"
#include "isotouch/run/replay.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/io/scene.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/tests/temp_dir.h"
#include "isotouch/io/volume_write.h"

#include <nlohmann/json.hpp>

namespace fs = std::filesystem;
using isotouch::core::Vec3;
using isotouch::io::load_recording;
using isotouch::io::RecordedTick;
using isotouch::io::Recording;
using isotouch::session::EditEvent;

namespace {

fs::path temp_dir(const std::string& tag) {
  const fs::path d = fs::temp_directory_path() / ("isotouch_test_replay_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

bool same_bits(double a, double b) { return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b); }
bool same_bits(const Vec3& a, const Vec3& b) { return same_bits(a.x, b.x) && same_bits(a.y, b.y) && same_bits(a.z, b.z); }


/// A synthetic sphere scene with a carve timeline (a carve away from the probe, then a
/// stroke of carves at the VHIP) and the button drill while in contact; written into `dir`.
std::string write_edit_scene(const fs::path& dir) {
  const auto v = isotouch::engine::make_sphere({48, 48, 48}, 1e-3, 15);
  const Vec3 side = v.grid.to_world(Vec3{38, 24, 24});  // +x side, away from the probe
  std::ostringstream text;
  text.precision(17);
  text << R"({"name": "record-sphere", "volume": {"synthetic": "sphere", "dims": [48, 48, 48], "spacing_m": 0.001,
              "radius_vox": 15}, "isovalue": 0, "inside": "above",
              "script": {"hold_s": 0.3, "stroke_length_m": 0.004},
              "outputs": {"plots": false},
              "edits": {"brush": {"kind": "drill", "radius_mm": 2, "force_threshold_n": 0.2, "rate": 3000},
                        "every_ticks": 7, "button": [[0.9, 1.05]],
                        "timeline": [{"t_s": 0.2, "kind": "carve", "at": [)"
       << side.x * 1e3 << ", " << side.y * 1e3 << ", " << side.z * 1e3 << R"(], "radius_mm": 3, "strength": 1000},
                                     {"t_s": 0.7, "kind": "carve", "at": "vhip", "radius_mm": 1.5, "strength": 0.3,
                                      "duration_s": 0.05}, {"t_s": 1.2, "kind": "undo"}]}})";
  const fs::path p = dir / "scene.json";
  std::ofstream(p) << text.str();
  return p.string();
}

struct Recorded {
  fs::path dir, scene, rec;
};

/// Runs the scene once with --record (shared by the tests below: a run costs seconds).
const Recorded& recorded_run() {
  static Recorded r = [] {
    Recorded x;
    x.dir = temp_dir("e2e");
    x.scene = write_edit_scene(x.dir);
    x.rec = x.dir / "run.rec";
    isotouch::run::RunOptions opt;
    opt.out_dir = (x.dir / "out").string();
    opt.progress = false;
    opt.record_path = x.rec.string();
    std::ostringstream log;
    (void)isotouch::run::run_scene(isotouch::io::load_scene(x.scene.string()), opt, log);
    return x;
  }();
  return r;
}

isotouch::run::ReplayResult replay(const Recording& rec, const std::string& out = "") {
  isotouch::run::ReplayOptions o;
  o.progress = false;
  o.out_dir = out;
  std::ostringstream log;
  return isotouch::run::replay_recording(rec, o, log);
}

/// Index of the first tick from `from` whose recorded force is non-zero (in contact).
std::size_t first_pressing_tick(const Recording& r, std::size_t from) {
  for (std::size_t k = from; k < r.ticks.size(); ++k)
    if (r.ticks[k].force_n.x != 0 || r.ticks[k].force_n.y != 0 || r.ticks[k].force_n.z != 0) return k;
  return r.ticks.size();
}

}  // namespace

TEST(Replay, ARecordedRunWithEditsReplaysToIdenticalForces) {
  const Recorded& x = recorded_run();
  const Recording rec = load_recording(x.rec.string());
  // The recording holds what the run did: every tick of trace.csv, timeline and button edits.
  long brushes = 0, undos = 0, button_ticks = 0;
  for (const auto& e : rec.edits) {
    brushes += e.kind == EditEvent::Kind::kBrush;
    undos += e.kind == EditEvent::Kind::kUndo;
  }
  for (const auto& t : rec.ticks) button_ticks += t.button;
  EXPECT_GT(brushes, 8);
  EXPECT_EQ(undos, 1);
  EXPECT_GT(button_ticks, 100);
  EXPECT_EQ(rec.scene_text, isotouch::test::slurp(x.scene));

  const auto r = replay(rec, (x.dir / "replay").string());
  EXPECT_EQ(r.ticks, long(rec.ticks.size()));
  EXPECT_EQ(r.edits, long(rec.edits.size()));
  EXPECT_GT(r.publications, 3);
  EXPECT_TRUE(r.identical()) << r.differing_ticks << " ticks differ, first " << r.first_diff_tick << ", max |dF| "
                             << r.max_df_n;
  EXPECT_EQ(r.max_df_n, 0.0);
  EXPECT_TRUE(fs::exists(x.dir / "replay" / "trace.csv"));
  // The forces are not all zero (the comparison compares something).
  EXPECT_LT(first_pressing_tick(rec, 0), rec.ticks.size());
}

TEST(Replay, OneHipMovedByOneUlpDiffersAtThatTick) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  const std::size_t k = first_pressing_tick(rec, 400);
  ASSERT_LT(k + 10, rec.ticks.size());
  Vec3& hip = rec.ticks[k + 10].hip_m;  // a tick in contact
  hip = {std::nextafter(hip.x, 1.0), std::nextafter(hip.y, 1.0), std::nextafter(hip.z, 1.0)};
  const auto r = replay(rec);
  EXPECT_FALSE(r.identical());
  EXPECT_EQ(r.first_diff_tick, long(k + 10));
  EXPECT_TRUE(same_bits(r.first_recorded_n, rec.ticks[k + 10].force_n));
  EXPECT_GT(r.max_df_n, 0.0);
}

TEST(Replay, OneEditsRadiusChangedDiffersAfterThatEdit) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  // The first brush applied while the probe presses (a carve at the VHIP or the drill).
  std::size_t i = 0;
  while (i < rec.edits.size() &&
         !(rec.edits[i].kind == EditEvent::Kind::kBrush && rec.edits[i].tick > 600)) ++i;
  ASSERT_LT(i, rec.edits.size());
  rec.edits[i].brush.radius_m *= 1.5;
  const auto r = replay(rec);
  EXPECT_FALSE(r.identical());
  // An edit's tick is the servo's tick count when it was applied (format 3): the ticks
  // before it read the snapshot before the edit and are unchanged.
  EXPECT_GE(r.first_diff_tick, rec.edits[i].tick);
  std::cout << "[ edit     ] radius of edit " << i << " (tick " << rec.edits[i].tick << ") x 1.5: first difference at tick "
            << r.first_diff_tick << ", " << r.differing_ticks << " ticks differ, max |dF| " << r.max_df_n << " N\n";
}

TEST(Replay, AnAbsurdHipInFreeSpaceIsNotIdentical) {
  // A HIP of 1e300 in a tick before any contact, the device at rest: the renderer sends zero
  // force as recorded and keeps the VHIP where it was, so force and VHIP agree; the replayed
  // tick is a fault and the recorded one was not.
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  ASSERT_EQ(rec.format_version, 3);  // `run --record` streams what `run --live --record` does
  const std::size_t k = 20;
  ASSERT_LT(k, first_pressing_tick(rec, 0)) << "tick 20 must be in free space";
  rec.ticks[k].hip_m = {1e300, rec.ticks[k].hip_m.y, rec.ticks[k].hip_m.z};
  const auto r = replay(rec);
  EXPECT_FALSE(r.identical());
  EXPECT_EQ(r.first_diff_tick, long(k));
  EXPECT_NE(r.first_diff_what.find("fault"), std::string::npos) << r.first_diff_what;
}

TEST(Replay, ARecordedSnapshotVersionThatDiffersIsNotIdentical) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  const std::size_t k = rec.ticks.size() / 2;
  ASSERT_GT(rec.ticks[k].version, 1u) << "the middle of the run reads an edited snapshot";
  rec.ticks[k].version -= 1;  // as if that tick had read the snapshot before
  const auto r = replay(rec);
  EXPECT_FALSE(r.identical());
  EXPECT_EQ(r.first_diff_tick, long(k));
  // The replay applies edits up to the version each tick recorded: one that no edit
  // brought it to shows as a different version, one that an edit did (tick k is the first
  // to read it) as the force and VHIP of the snapshot before.
  EXPECT_TRUE(r.first_diff_what == "snapshot version" || r.first_diff_what.find("force") == 0) << r.first_diff_what;
}

// A killed live session's FILE.part may end with ticks that read a snapshot whose edit was
// written after the cut: those are left out of the comparison (and counted), only in a cut
// recording; the same file with its end record is a difference.
TEST(Replay, ACutRecordingLeavesOutTheTicksThatReadAnEditWrittenAfterTheCut) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  ASSERT_EQ(rec.format_version, 3);
  // k_new: the first tick reading the last version; k_prev: the first reading the one before.
  const std::uint64_t last_v = rec.ticks.back().version;
  std::size_t k_new = 0;
  while (rec.ticks[k_new].version != last_v) ++k_new;
  ASSERT_GT(k_new, 0u);
  std::size_t k_prev = 0;
  while (rec.ticks[k_prev].version != rec.ticks[k_new - 1].version) ++k_prev;
  // The cut: the edits applied after tick k_prev are missing, 10 ticks after k_new remain.
  while (!rec.edits.empty() && rec.edits.back().tick > long(k_prev)) rec.edits.pop_back();
  ASSERT_LT(k_new + 10, rec.ticks.size());
  rec.ticks.resize(k_new + 10);
  rec.complete = false;
  const auto cut = replay(rec);
  EXPECT_TRUE(cut.identical()) << cut.differing_ticks << " ticks differ, first " << cut.first_diff_tick;
  EXPECT_EQ(cut.ticks, long(k_new));
  EXPECT_EQ(cut.cut_ticks, 10);
  rec.complete = true;  // the same ticks and edits with an end record: a difference
  const auto whole = replay(rec);
  EXPECT_FALSE(whole.identical());
  EXPECT_EQ(whole.first_diff_tick, long(k_new));
  EXPECT_EQ(whole.cut_ticks, 0);
}

TEST(Replay, AnotherVolumeIsRefused) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  ASSERT_TRUE(rec.volume_crc32.has_value());
  *rec.volume_crc32 ^= 1u;  // as if the volume file had changed since
  try {
    (void)replay(rec);
    ADD_FAILURE() << "replayed against another volume";
  } catch (const isotouch::run::ReplayInputError& e) {
    EXPECT_NE(std::string(e.what()).find("changed since it was recorded (CRC-32"), std::string::npos) << e.what();
  }
}

TEST(Replay, VolumeChecksumSeesOneVoxel) {
  auto v = isotouch::engine::make_sphere({16, 16, 16}, 1e-3, 5);
  const std::uint32_t before = isotouch::io::volume_crc32(v);
  v.voxels[1000] = std::nextafter(v.voxels[1000], 1e30f);
  EXPECT_NE(isotouch::io::volume_crc32(v), before);
  auto w = isotouch::engine::make_sphere({16, 16, 16}, 1e-3, 5);
  w.grid.spacing_m.z *= 1.5;  // the same voxels, resampled
  EXPECT_NE(isotouch::io::volume_crc32(w), before);
}

// The recording carries the scene's text: replay runs it, wherever the scene file is now and
// whatever it holds; the text, not the file, is what it runs.
TEST(Replay, TheRecordedSceneTextRunsWhereverTheFileIsNow) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  rec.scene_path = (temp_dir("gone") / "moved-away.json").string();  // no file there
  const auto r = replay(rec);
  EXPECT_TRUE(r.identical()) << r.differing_ticks << " ticks differ, first " << r.first_diff_tick;
  EXPECT_EQ(r.edits, long(rec.edits.size()));
  // Another stiffness in the recorded text (the file unchanged): other forces.
  const std::string k = "\"script\"";
  ASSERT_NE(rec.scene_text.find(k), std::string::npos);
  rec.scene_text.replace(rec.scene_text.find(k), k.size(), "\"servo\": {\"stiffness_n_per_m\": 900}, " + k);
  EXPECT_FALSE(replay(rec).identical());
  // Text that is not a scene is refused, naming the recording and the field.
  rec.scene_text = "{\"volume\": 3}";
  try {
    (void)replay(rec);
    ADD_FAILURE() << "replayed a scene text that is not a scene";
  } catch (const isotouch::run::ReplayInputError& e) {
    EXPECT_NE(std::string(e.what()).find("recording: the scene it carries (recorded from "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("volume"), std::string::npos) << e.what();
  }
}

// A volume file named relative to the scene: found in the folder the scene was in when
// recorded, from a recording elsewhere, with the scene file since changed; checked by CRC.
TEST(Replay, ARelativeVolumeIsFoundBesideTheRecordedSceneAndCheckedByCrc) {
  const fs::path dir = temp_dir("relvol");
  isotouch::io::save_volume_itk(isotouch::engine::make_sphere({32, 32, 32}, 1e-3, 10), (dir / "ball.nrrd").string());
  const std::string scene = (dir / "ball.json").string();
  std::ofstream(scene) << R"({"name": "ball", "volume": {"path": "ball.nrrd"}, "isovalue": 0, "inside": "above",
                              "script": {"hold_s": 0.05, "stroke_length_m": 0.002}, "outputs": {"plots": false}})";
  isotouch::run::RunOptions opt;
  opt.out_dir = (dir / "out").string();
  opt.progress = false;
  opt.record_path = (dir / "ball.rec").string();
  std::ostringstream log;
  (void)isotouch::run::run_scene(isotouch::io::load_scene(scene), opt, log);
  const Recording rec = load_recording(opt.record_path);
  std::ofstream(scene) << "{}";  // the scene file changed since
  isotouch::run::ReplayOptions o;
  o.progress = false;
  o.recording_dir = temp_dir("relvol-elsewhere").string();
  const auto r = isotouch::run::replay_recording(rec, o, log);
  EXPECT_TRUE(r.identical()) << r.differing_ticks << " ticks differ";
  EXPECT_GT(r.ticks, 100);
  isotouch::io::save_volume_itk(isotouch::engine::make_sphere({32, 32, 32}, 1e-3, 9), (dir / "ball.nrrd").string());
  try {
    (void)isotouch::run::replay_recording(rec, o, log);
    ADD_FAILURE() << "replayed against another volume";
  } catch (const isotouch::run::ReplayInputError& e) {
    EXPECT_NE(std::string(e.what()).find("ball.nrrd changed since it was recorded (CRC-32"), std::string::npos) << e.what();
  }
}

// Edits through an edit session the scene does not describe (the sculpting app's brushes on a
// scene without "edits"): the recording's edit_session builds it, and the run replays.
TEST(Replay, TheRecordedEditSessionReplaysEditsOfASceneWithoutEdits) {
  const Recorded& x = recorded_run();
  Recording rec = load_recording(x.rec.string());
  nlohmann::json scene = nlohmann::json::parse(rec.scene_text);
  // The recorded run felt its button brush as the tool of the brush's radius; without the
  // "edits" section the scene says so itself, as the app's scenes do.
  const isotouch::io::Scene parsed = isotouch::io::parse_scene(rec.scene_text, rec.scene_path);
  if (parsed.hri.tool_radius_m > 0) scene["servo"]["tool"] = {{"radius_mm", parsed.hri.tool_radius_m * 1e3}};
  scene.erase("edits");
  rec.scene_text = scene.dump();
  try {
    (void)replay(rec);
    ADD_FAILURE() << "replayed edits without an edit session";
  } catch (const isotouch::run::ReplayInputError& e) {
    EXPECT_NE(std::string(e.what()).find("has no \"edits\" section and the recording no edit_session"), std::string::npos)
        << e.what();
  }
  // The session's edit ease period is the recorded run's (its scene's every_ticks / rate):
  // without it the scene stripped of "edits" would ease over another period.
  const double period = 7.0 / 1000.0;
  rec.edit_session = isotouch::io::RecordedEditSession{true, 256, 0};
  EXPECT_FALSE(replay(rec).identical()) << "the edit period is not the recorded one, yet the forces are the same";
  rec.edit_session = isotouch::io::RecordedEditSession{true, 256, period};
  const auto r = replay(rec);
  EXPECT_TRUE(r.identical()) << r.differing_ticks << " ticks differ, first " << r.first_diff_tick;
  EXPECT_EQ(r.edits, long(rec.edits.size()));
  EXPECT_GT(r.publications, 3);
}
