// Edits in scenes: session::EditSession (undo / redo bit for bit, the
// snapshot it publishes), the headless loop's after-tick hook (what it publishes, the next
// tick reads), run_scene with a timeline (carve at the VHIP lands at that tick's VHIP; the
// removed volume) and the drill-skull scene (the burr goes through the bone).
// Truth from outside the code under test: brute-force voxel counts over the volume, the
// sparse CPU reference (run_sparse_cpu) on the unedited volume, trace.csv, this file's own
// trilinear interpolation along the press ray, and the .vdb written by the run read back.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "isotouch/session/edit_session.h"
#include "isotouch/core/field_view.h"
#include "isotouch/sim/headless.h"
#include "isotouch/io/record.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/io/scene.h"
#include "isotouch/engine/sparse_chain.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/tests/vk_test_context.h"
#include "isotouch/tests/voxel_probe.h"

namespace fs = std::filesystem;
using isotouch::session::EditEvent;
using isotouch::session::EditSession;
using isotouch::session::EditOutcome;
using isotouch::session::Brush;
using isotouch::session::BrushKind;
using isotouch::engine::Volume;
using isotouch::core::Vec3;

namespace {
const std::string kScenes = std::string(ISOTOUCH_TEST_DATA) + "/../scenes";

isotouch::session::LiveFieldOptions sphere_options() {
  // Every member given (the default pass list trips GCC 12's -Wmaybe-uninitialized).
  return isotouch::session::LiveFieldOptions{{isotouch::engine::PassDesc::gradient()},
                                            isotouch::core::Isosurface{0.0, isotouch::core::InsideIs::kAbove},
                                            -100.f, isotouch::core::SampleFormat::kFp32};
}

bool same_bits(const Volume& a, const Volume& b) {
  return a.voxels.size() == b.voxels.size() &&
         std::memcmp(a.voxels.data(), b.voxels.data(), a.voxels.size() * sizeof(float)) == 0;
}

// Value and gradient at every voxel centre, through the servo's FieldView, equal bit for bit.
void expect_same_field(const isotouch::core::SampleField& a, const isotouch::core::SampleField& b) {
  const isotouch::core::FieldView va(a), vb(b);
  const auto& g = b.grid;
  long diff = 0;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) {
        const Vec3 w = g.to_world(Vec3{double(i), double(j), double(k)});
        const auto x = va.value_gradient(w), y = vb.value_gradient(w);
        if (std::memcmp(&x.value, &y.value, sizeof x.value) != 0 || x.gradient.x != y.gradient.x ||
            x.gradient.y != y.gradient.y || x.gradient.z != y.gradient.z)
          ++diff;
      }
  EXPECT_EQ(diff, 0) << "voxel centres where the snapshots differ";
}

Brush carve_at(const Volume& v, std::array<int, 3> idx, double radius_m, double strength) {
  Brush b;
  b.kind = BrushKind::kCarve;
  b.centre_m = v.grid.to_world(Vec3{double(idx[0]), double(idx[1]), double(idx[2])});
  b.radius_m = radius_m;
  b.strength = strength;
  b.falloff = 0.5;
  b.targets = isotouch::session::default_targets(v, sphere_options().iso);
  return b;
}

EditEvent brush_event(const Brush& b) {
  EditEvent e;
  e.kind = EditEvent::Kind::kBrush;
  e.brush = b;
  return e;
}
EditEvent plain(EditEvent::Kind k) {
  EditEvent e;
  e.kind = k;
  return e;
}

void undo_redo_round_trip(isotouch::engine::VulkanContext* ctx) {
  const Volume original = isotouch::engine::make_sphere({40, 40, 40}, 1e-3, 12);
  EditSession s(Volume(original), ctx, sphere_options(), 16.0);
  s.sculptor().set_cpu_max_bricks(0);  // with a device: every brush there (the device path's test)
  isotouch::servo::TripleBuffer<isotouch::core::SampleField> buf;
  buf.publish(s.current());
  EXPECT_EQ(buf.acquire()->version, 1u);

  // One stroke of two carves, then an add of its own.
  s.apply(plain(EditEvent::Kind::kBeginStroke), &buf);
  auto o1 = s.apply(brush_event(carve_at(original, {20, 20, 31}, 4e-3, 3.0)), &buf);
  auto o2 = s.apply(brush_event(carve_at(original, {22, 20, 31}, 4e-3, 3.0)), &buf);
  s.apply(plain(EditEvent::Kind::kEndStroke), &buf);
  EXPECT_TRUE(o1.published);
  EXPECT_FALSE(o1.brush.dirty.empty());
  EXPECT_GT(o2.update.version, o1.update.version);
  const Volume carved = s.volume();
  EXPECT_FALSE(same_bits(carved, original));
  Brush add = carve_at(original, {20, 31, 20}, 3e-3, 2.0);
  add.kind = BrushKind::kAdd;
  s.apply(brush_event(add), &buf);
  const Volume edited = s.volume();
  const std::uint64_t v_edited = buf.acquire()->version;
  EXPECT_EQ(v_edited, s.current()->version);

  // Undo twice: the original bits, and a published snapshot that reads like the sparse
  // CPU reference on the original volume.
  auto u1 = s.apply(plain(EditEvent::Kind::kUndo), &buf);
  EXPECT_TRUE(u1.published);
  EXPECT_FALSE(u1.restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), carved));
  s.apply(plain(EditEvent::Kind::kUndo), &buf);
  EXPECT_TRUE(same_bits(s.volume(), original));
  const auto* after_undo = buf.acquire();
  EXPECT_GT(after_undo->version, v_edited);
  const auto o = sphere_options();
  const auto ref = isotouch::engine::run_sparse_cpu(original, o.passes, o.iso, o.background, o.format);
  expect_same_field(*after_undo, ref.field);

  // Redo twice: the edited bits back.
  s.apply(plain(EditEvent::Kind::kRedo), &buf);
  EXPECT_TRUE(same_bits(s.volume(), carved));
  s.apply(plain(EditEvent::Kind::kRedo), &buf);
  EXPECT_TRUE(same_bits(s.volume(), edited));
  const auto ref2 = isotouch::engine::run_sparse_cpu(edited, o.passes, o.iso, o.background, o.format);
  expect_same_field(*buf.acquire(), ref2.field);
  EXPECT_EQ(s.log().size(), 9u);  // every event, in order
  EXPECT_EQ(s.log()[4].kind, EditEvent::Kind::kBrush);
  EXPECT_EQ(s.log()[8].kind, EditEvent::Kind::kRedo);
}

// Inside voxels (value > 0 on the positive-inside sphere).
long inside(const Volume& v) {
  long n = 0;
  for (float x : v.voxels) n += x > 0.f;
  return n;
}

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

struct TraceRow {
  double t, hip[3], vhip[3], f;
  bool contact;
};
std::vector<TraceRow> read_trace(const fs::path& csv) {
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  std::vector<TraceRow> rows;
  while (std::getline(in, line)) {
    std::vector<double> c;
    std::istringstream s(line);
    std::string tok;
    while (std::getline(s, tok, ',')) c.push_back(std::stod(tok));
    if (c.size() < 11) break;
    rows.push_back({c[0], {c[1], c[2], c[3]}, {c[4], c[5], c[6]}, std::sqrt(c[7] * c[7] + c[8] * c[8] + c[9] * c[9]),
                    c[10] != 0});
  }
  return rows;
}
std::vector<std::map<std::string, std::string>> read_csv(const fs::path& csv) {
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  std::vector<std::string> head;
  {
    std::istringstream s(line);
    for (std::string t; std::getline(s, t, ',');) head.push_back(t);
  }
  std::vector<std::map<std::string, std::string>> rows;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::map<std::string, std::string> r;
    std::size_t i = 0;
    for (std::string t; std::getline(s, t, ',') && i < head.size(); ++i) r[head[i]] = t;
    rows.push_back(r);
  }
  return rows;
}

// Trilinear value at a grid-world point (identity direction); NaN outside the voxel box.
double trilinear(const Volume& v, const Vec3& p) { return isotouch::test::trilinear_grid(v, p); }
}  // namespace

TEST(EditSession, UndoThenRedoIsBitForBitAndPublishesCpu) { undo_redo_round_trip(nullptr); }

TEST(EditSession, UndoThenRedoIsBitForBitAndPublishesGpu) {
  auto& vk = isotouch::test::validated_vk();
  undo_redo_round_trip(&vk);
  EXPECT_EQ(vk.validation_messages(), 0u);
}

// A carve strong enough to empty every voxel it reaches removes exactly the inside voxels
// within its radius (brute force over the volume: the brush's reach is r < radius).
TEST(EditSession, CarveRemovesTheBruteForceVoxels) {
  const Volume v = isotouch::engine::make_sphere({48, 48, 48}, 1e-3, 16);
  const std::array<int, 3> c{24, 24, 39};  // a voxel centre near the top of the sphere
  const double radius = 5e-3;              // integer squared distances: no voxel at exactly r = radius
  long expect = 0;
  for (int k = 0; k < 48; ++k)
    for (int j = 0; j < 48; ++j)
      for (int i = 0; i < 48; ++i) {
        const long d2 = long(i - c[0]) * (i - c[0]) + long(j - c[1]) * (j - c[1]) + long(k - c[2]) * (k - c[2]);
        if (d2 < 25 && v.voxels[v.grid.index(i, j, k)] > 0.f) ++expect;
      }
  ASSERT_GT(expect, 50);
  EditSession s(Volume(v), nullptr, sphere_options());
  s.apply(brush_event(carve_at(v, c, radius, 1e9)), nullptr);
  EXPECT_EQ(inside(v) - inside(s.volume()), expect);
}

// A brush whose target an fp16 snapshot cannot hold (|v| > 65504) is refused BEFORE the
// volume changes: the volume, the snapshot and the log stay as they were (review finding:
// the volume was edited, then LiveField::update refused the new values).
TEST(EditSession, UnstorableTargetIsRefusedBeforeTheVolumeChanges) {
  const Volume v = isotouch::engine::make_sphere({32, 32, 32}, 1e-3, 10);
  auto opt = sphere_options();
  opt.format = isotouch::core::SampleFormat::kFp16;
  EditSession s(Volume(v), nullptr, opt);
  const auto before = s.current();
  Brush b = carve_at(v, {16, 16, 25}, 4e-3, 10.0);
  b.kind = BrushKind::kAdd;
  b.targets.material = 70000.f;
  EXPECT_THROW(s.apply(brush_event(b), nullptr), isotouch::session::BrushError);
  EXPECT_EQ(std::memcmp(s.volume().voxels.data(), v.voxels.data(), v.voxels.size() * sizeof(float)), 0);
  EXPECT_EQ(s.current(), before);
  EXPECT_TRUE(s.log().empty());
  b.targets.material = 60000.f;  // storable: applied and published
  EXPECT_TRUE(s.apply(brush_event(b), nullptr).published);
}

// A brush refused by its own checks (here a radius of 0) changes nothing and takes no undo
// step with it: the one before it is still there (a refused brush must not roll back the
// previous brush's stroke).
TEST(EditSession, ARefusedBrushLeavesThePreviousUndoStep) {
  const Volume v = isotouch::engine::make_sphere({32, 32, 32}, 1e-3, 10);
  EditSession s(Volume(v), nullptr, sphere_options());
  ASSERT_TRUE(s.apply(brush_event(carve_at(v, {16, 16, 25}, 4e-3, 1e9)), nullptr).published);
  const Volume after = s.volume();
  const auto snap = s.current();
  ASSERT_EQ(s.sculptor().history().undo_depth(), 1u);
  Brush bad = carve_at(v, {16, 16, 20}, 4e-3, 1e9);
  bad.radius_m = 0;
  EXPECT_THROW(s.apply(brush_event(bad), nullptr), isotouch::session::BrushError);
  EXPECT_EQ(std::memcmp(s.volume().voxels.data(), after.voxels.data(), v.voxels.size() * sizeof(float)), 0);
  EXPECT_EQ(s.current(), snap);
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u);
  EXPECT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  EXPECT_EQ(std::memcmp(s.volume().voxels.data(), v.voxels.data(), v.voxels.size() * sizeof(float)), 0);
}

// The edit log keeps at most log_limit() events (a long live session must not grow without
// bound); the ones past it are counted, and every event is still applied.
TEST(EditSession, TheEditLogIsBounded) {
  const Volume v = isotouch::engine::make_sphere({32, 32, 32}, 1e-3, 10);
  EditSession s(Volume(v), nullptr, sphere_options());
  s.set_log_limit(3);
  for (int i = 0; i < 5; ++i) s.apply(brush_event(carve_at(v, {16, 16, 20 + i}, 2e-3, 1e9)), nullptr);
  EXPECT_EQ(s.log().size(), 3u);
  EXPECT_EQ(s.log_dropped(), 2u);
  // All five were applied: the volume equals one where all five were logged.
  EditSession all(Volume(v), nullptr, sphere_options());
  for (int i = 0; i < 5; ++i) all.apply(brush_event(carve_at(v, {16, 16, 20 + i}, 2e-3, 1e9)), nullptr);
  EXPECT_EQ(all.log().size(), 5u);
  EXPECT_EQ(std::memcmp(s.volume().voxels.data(), all.volume().voxels.data(), v.voxels.size() * sizeof(float)), 0);
  s.set_log_limit(1);  // lowering it drops the tail
  EXPECT_EQ(s.log().size(), 1u);
  EXPECT_EQ(s.log_dropped(), 4u);
}

// When the new snapshot cannot be built (here a std::bad_alloc thrown where LiveField::update
// runs), or a brush fails after it wrote its voxels (thrown right after the brush; its undo
// step would be recorded only once its snapshot is out), apply() takes the edit back: the volume equals the one current()
// was built from, nothing is published or logged, and the undo history is as before (a
// brush leaves no phantom undo step; with the update's fault, an undo is redone). Truth: the volumes of a session
// that never saw the failing edit, bit for bit.
enum class FaultAt { kUpdate, kBrush };
void failed_edit_is_taken_back(isotouch::engine::VulkanContext* ctx, FaultAt at) {
  const Volume v = isotouch::engine::make_sphere({40, 40, 40}, 1e-3, 12);
  EditSession s(Volume(v), ctx, sphere_options(), 16.0);
  s.sculptor().set_cpu_max_bricks(0);  // with a device: every brush there (the device path's test)
  const Brush a = carve_at(v, {20, 20, 31}, 4e-3, 1e9);
  const Brush b = carve_at(v, {20, 31, 20}, 4e-3, 1e9);
  ASSERT_TRUE(s.apply(brush_event(a), nullptr).published);
  const Volume after_a = s.volume();
  const auto snap_a = s.current();
  bool fail = true;
  const auto fault = [&] {
    if (fail) throw std::bad_alloc();
  };
  if (at == FaultAt::kUpdate) s.set_update_fault_for_test(fault);
  else s.set_brush_fault_for_test(fault);

  // A brush of its own stroke, and one inside an open stroke.
  EXPECT_THROW(s.apply(brush_event(b), nullptr), std::bad_alloc);
  EXPECT_TRUE(same_bits(s.volume(), after_a));
  EXPECT_EQ(s.current(), snap_a);
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u);
  s.apply(plain(EditEvent::Kind::kBeginStroke), nullptr);
  EXPECT_THROW(s.apply(brush_event(b), nullptr), std::bad_alloc);
  EXPECT_TRUE(same_bits(s.volume(), after_a));
  s.apply(plain(EditEvent::Kind::kEndStroke), nullptr);
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u);

  // An undo that fails is redone: the carve is still there and still undoable.
  if (at == FaultAt::kUpdate) {
    EXPECT_THROW(s.apply(plain(EditEvent::Kind::kUndo), nullptr), std::bad_alloc);
    EXPECT_TRUE(same_bits(s.volume(), after_a));
    EXPECT_EQ(s.current(), snap_a);
    EXPECT_EQ(s.sculptor().history().undo_depth(), 1u);
    EXPECT_EQ(s.sculptor().history().redo_depth(), 0u);
  }
  EXPECT_EQ(s.log().size(), 3u);  // a, begin, end: the failed events are not logged

  // Without the fault the same events work, and the GPU copy was rolled back too: the
  // session ends bit for bit where a session that never failed ends.
  fail = false;
  ASSERT_TRUE(s.apply(brush_event(b), nullptr).published);
  EditSession ref(Volume(v), ctx, sphere_options(), 16.0);  // the same device: the same bits
  ref.sculptor().set_cpu_max_bricks(0);
  ref.apply(brush_event(a), nullptr);
  ref.apply(brush_event(b), nullptr);
  EXPECT_TRUE(same_bits(s.volume(), ref.volume()));
  expect_same_field(*s.current(), *ref.current());
  ASSERT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  ASSERT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), v));
  EXPECT_TRUE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  // A failed brush after the undos keeps the redo branch a new stroke would have dropped.
  ASSERT_EQ(s.sculptor().history().redo_depth(), 2u);
  fail = true;
  EXPECT_THROW(s.apply(brush_event(b), nullptr), std::bad_alloc);
  EXPECT_TRUE(same_bits(s.volume(), v));
  EXPECT_EQ(s.sculptor().history().redo_depth(), 2u) << "the failed brush dropped the redo branch";
  EXPECT_EQ(s.sculptor().history().undo_depth(), 0u);
  fail = false;
  ASSERT_FALSE(s.apply(plain(EditEvent::Kind::kRedo), nullptr).restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), after_a));
  ASSERT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  if (auto* eng = s.sculptor().engine()) {
    const std::vector<float> dev = eng->download_all();
    EXPECT_EQ(std::memcmp(dev.data(), v.voxels.data(), v.voxels.size() * sizeof(float)), 0) << "GPU copy";
  }
}

TEST(EditSession, AFailedSnapshotUpdateTakesTheEditBackCpu) { failed_edit_is_taken_back(nullptr, FaultAt::kUpdate); }

TEST(EditSession, AFailedSnapshotUpdateTakesTheEditBackGpu) {
  auto& vk = isotouch::test::validated_vk();
  failed_edit_is_taken_back(&vk, FaultAt::kUpdate);
  EXPECT_EQ(vk.validation_messages(), 0u);
}

TEST(EditSession, ABrushThatFailsPartWayTakesItselfBackCpu) { failed_edit_is_taken_back(nullptr, FaultAt::kBrush); }

TEST(EditSession, ABrushThatFailsPartWayTakesItselfBackGpu) {
  auto& vk = isotouch::test::validated_vk();
  failed_edit_is_taken_back(&vk, FaultAt::kBrush);
  EXPECT_EQ(vk.validation_messages(), 0u);
}

// A brush whose stroke would fit the undo history's memory limit only by pushing the older
// stroke out, and whose snapshot then fails, leaves the history as it was: its undo step is
// recorded only once its snapshot is out, so the older stroke is not pushed out for an edit
// that was taken back. Truth: the volume after the first brush, bit for bit, and an undo
// that restores the unedited volume.
TEST(EditSession, AFailedBrushLeavesTheHistoryAsItWas) {
  const Volume v = isotouch::engine::make_sphere({40, 40, 40}, 1e-3, 12);
  const Brush a = carve_at(v, {20, 20, 31}, 4e-3, 1e9);
  const Brush b = carve_at(v, {20, 31, 20}, 4e-3, 1e9);
  const auto stroke_bytes = [&](const Brush& x) {
    EditSession m(Volume(v), nullptr, sphere_options(), 16.0);
    m.apply(brush_event(x), nullptr);
    return m.sculptor().history().bytes();
  };
  const std::uint64_t bytes_a = stroke_bytes(a), bytes_b = stroke_bytes(b);
  const double limit = 1.25 * double(std::max(bytes_a, bytes_b));  // room for either, not both
  ASSERT_LT(limit, double(bytes_a + bytes_b));
  EditSession s(Volume(v), nullptr, sphere_options(), limit / double(1u << 20));
  ASSERT_TRUE(s.apply(brush_event(a), nullptr).published);
  ASSERT_EQ(s.sculptor().history().undo_depth(), 1u);
  const Volume after_a = s.volume();
  s.set_update_fault_for_test([] { throw std::bad_alloc(); });
  EXPECT_THROW(s.apply(brush_event(b), nullptr), std::bad_alloc);
  s.set_update_fault_for_test({});
  EXPECT_TRUE(same_bits(s.volume(), after_a));
  EXPECT_EQ(s.sculptor().history().dropped_strokes(), 0u) << "the failed brush pushed a's stroke out";
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u);
  EXPECT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), v));
}

// The undo step is recorded after the snapshot is published, from the volume as of the
// snapshot before. When it cannot be recorded the edit stands (published, the volume and
// the snapshot agree) and the whole history goes, said in the outcome: undoing the older
// stroke past the edit would give a state that never existed. Truth: what the triple buffer
// holds, the volume against a session that never failed, and an undo that restores nothing.
TEST(EditSession, AnUndoStepThatCannotBeRecordedDropsTheHistory) {
  const Volume v = isotouch::engine::make_sphere({40, 40, 40}, 1e-3, 12);
  const Brush a = carve_at(v, {20, 20, 31}, 4e-3, 1e9);
  const Brush b = carve_at(v, {20, 31, 20}, 4e-3, 1e9);
  EditSession s(Volume(v), nullptr, sphere_options(), 16.0);
  isotouch::servo::TripleBuffer<isotouch::core::SampleField> buf;
  ASSERT_TRUE(s.apply(brush_event(a), &buf).published);
  s.set_history_fault_for_test([] { throw std::bad_alloc(); });
  const EditOutcome o = s.apply(brush_event(b), &buf);
  s.set_history_fault_for_test({});
  EXPECT_TRUE(o.published);
  EXPECT_FALSE(o.history_error.empty());
  EXPECT_EQ(buf.acquire(), s.current().get()) << "the edit's snapshot is the one published";
  EditSession ref(Volume(v), nullptr, sphere_options(), 16.0);
  ref.apply(brush_event(a), nullptr);
  ref.apply(brush_event(b), nullptr);
  EXPECT_TRUE(same_bits(s.volume(), ref.volume()));
  expect_same_field(*s.current(), *ref.current());
  EXPECT_EQ(s.sculptor().history().undo_depth(), 0u);
  EXPECT_EQ(s.sculptor().history().bytes(), 0u);
  EXPECT_TRUE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), ref.volume()));
  // The next brush records its step again.
  const EditOutcome o2 = s.apply(brush_event(carve_at(v, {31, 20, 20}, 4e-3, 1e9)), &buf);
  EXPECT_TRUE(o2.history_error.empty());
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u);
  EXPECT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), ref.volume()));
}

// Inside a press (begin_stroke .. end_stroke) a step that cannot be recorded drops the
// history but not the press: the brushes after it are still one undo step, and that step
// takes the volume back to where the failed recording left it. A brush that changes nothing
// records nothing, so a fault there drops nothing. Truth: a session that never failed,
// bit for bit.
TEST(EditSession, ADroppedHistoryKeepsThePressOneStep) {
  const Volume v = isotouch::engine::make_sphere({40, 40, 40}, 1e-3, 12);
  const Brush a = carve_at(v, {20, 20, 31}, 4e-3, 1e9);
  const Brush b = carve_at(v, {20, 31, 20}, 4e-3, 1e9);
  const Brush c = carve_at(v, {31, 20, 20}, 4e-3, 1e9);
  const Brush d = carve_at(v, {20, 20, 9}, 4e-3, 1e9);
  EditSession s(Volume(v), nullptr, sphere_options(), 16.0);
  ASSERT_TRUE(s.apply(brush_event(a), nullptr).published);
  s.apply(plain(EditEvent::Kind::kBeginStroke), nullptr);
  s.set_history_fault_for_test([] { throw std::bad_alloc(); });
  const EditOutcome again = s.apply(brush_event(a), nullptr);  // a again: changes nothing
  EXPECT_FALSE(again.published);
  EXPECT_TRUE(again.history_error.empty());
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u) << "a brush that changed nothing dropped the history";
  EXPECT_FALSE(s.apply(brush_event(b), nullptr).history_error.empty());
  s.set_history_fault_for_test({});
  EXPECT_EQ(s.sculptor().history().undo_depth(), 0u);
  const Volume after_b = s.volume();
  ASSERT_TRUE(s.apply(brush_event(c), nullptr).published);
  ASSERT_TRUE(s.apply(brush_event(d), nullptr).published);
  s.apply(plain(EditEvent::Kind::kEndStroke), nullptr);
  EXPECT_EQ(s.sculptor().history().undo_depth(), 1u) << "c and d are one step of the press";
  EXPECT_FALSE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
  EXPECT_TRUE(same_bits(s.volume(), after_b));
  EXPECT_TRUE(s.apply(plain(EditEvent::Kind::kUndo), nullptr).restored.empty());
}

// The hook runs after tick k's render; what it publishes, tick k + 1 reads; without a hook
// the trace is what it was.
TEST(Headless, HookPublishesBeforeTheNextTick) {
  const std::string text = R"({"volume": {"synthetic": "sphere", "dims": [32, 32, 32], "radius_vox": 10},
                               "isovalue": 0, "script": {"hold_s": 0.05, "stroke_length_m": 0.005}})";
  const auto scene = isotouch::io::parse_scene(text, "hook.json");
  const Volume v = isotouch::engine::make_sphere({32, 32, 32}, 1e-3, 10);
  const auto o = sphere_options();
  auto base = std::make_shared<isotouch::core::SampleField>(
      isotouch::engine::run_sparse_cpu(v, o.passes, o.iso, o.background, o.format).field);
  base->version = 1;
  const auto script = isotouch::sim::make_touch_script(*base, scene.hri, scene.script);
  auto run = [&](const isotouch::sim::TickHook& hook, isotouch::servo::TripleBuffer<isotouch::core::SampleField>& buf) {
    isotouch::servo::WorkspaceTransform xf;
    xf.translation_m = v.grid.centre_m();
    Vec3 p, vel;
    script.at(0, p, vel);
    isotouch::sim::SimDevice dev(scene.device, xf.to_device(p));
    isotouch::servo::HriRenderer r(scene.hri);
    return isotouch::sim::run_headless(buf, r, dev, xf, script, scene.hri.rate_hz, {}, 250, hook);
  };
  isotouch::servo::TripleBuffer<isotouch::core::SampleField> b1, b2, b3;
  b1.publish(base);
  b2.publish(base);
  b3.publish(base);
  const auto plain_trace = run({}, b1);
  // A hook that publishes nothing: the same trace bit for bit (the button it sets aside).
  const auto quiet = run([](long k, isotouch::sim::TraceRow& row) { row.button = (k % 2) == 1; }, b2);
  ASSERT_EQ(plain_trace.size(), quiet.size());
  for (std::size_t k = 0; k < quiet.size(); ++k) {
    EXPECT_EQ(quiet[k].button, (k % 2) == 1);
    EXPECT_FALSE(plain_trace[k].button);
    EXPECT_EQ(quiet[k].version, 1u);
    EXPECT_EQ(std::memcmp(&plain_trace[k].force_n, &quiet[k].force_n, sizeof(Vec3)), 0) << "tick " << k;
    EXPECT_EQ(std::memcmp(&plain_trace[k].hip_m, &quiet[k].hip_m, sizeof(Vec3)), 0) << "tick " << k;
  }
  // Same samples under a new version after every tick k: tick k + 1 must read version k + 2.
  const auto hooked = run(
      [&](long k, isotouch::sim::TraceRow&) {
        auto f = std::make_shared<isotouch::core::SampleField>(*base);
        f->version = std::uint64_t(k + 2);
        b3.publish(f);
      },
      b3);
  ASSERT_EQ(plain_trace.size(), hooked.size());
  for (std::size_t k = 0; k < hooked.size(); ++k) ASSERT_EQ(hooked[k].version, k + 1) << "tick " << k;
}

// The sphere scene with a timeline: a carve at a fixed point before contact, a carve at the
// VHIP during contact (a stroke of applications). Each "vhip" application is centred on the
// VHIP that trace.csv lists for its tick; the snapshot version grows; the removed volume in
// summary.json is the inside voxels of the input minus those of drilled.vdb read back.
TEST(RunEdits, SphereTimelineCarves) {
  const Volume v = isotouch::engine::make_sphere({64, 64, 64}, 1e-3, 20);
  const Vec3 side = v.grid.to_world(Vec3{52, 32, 32});  // on the sphere's +x side, away from the probe
  std::ostringstream text;
  text.precision(17);
  text << R"({"name": "sphere-edits", "volume": {"synthetic": "sphere", "dims": [64, 64, 64], "spacing_m": 0.001,
              "radius_vox": 20}, "isovalue": 0, "inside": "above",
              "script": {"hold_s": 0.2, "stroke_length_m": 0.0},
              "outputs": {"plots": false},
              "edits": {"brush": {"kind": "carve", "radius_mm": 3, "strength": 1000}, "every_ticks": 10,
                        "timeline": [{"t_s": 0.2, "kind": "carve", "at": [)"
       << side.x * 1e3 << ", " << side.y * 1e3 << ", " << side.z * 1e3 << R"(]},
                                     {"t_s": 1.05, "kind": "carve", "at": "vhip", "radius_mm": 1.5, "strength": 0.3,
                                      "duration_s": 0.1}]}})";
  const auto scene = isotouch::io::parse_scene(text.str(), "sphere-edits.json");
  const fs::path out = temp_dir("isotouch_edits_sphere");
  isotouch::run::RunOptions opt;
  opt.out_dir = out.string();
  opt.progress = false;
  std::ostringstream log;
  const auto m = isotouch::run::run_scene(scene, opt, log);
  ASSERT_TRUE(m.edits.present);
  EXPECT_EQ(m.edits.timeline_brushes, 11);  // 1 + ceil(100 ticks / 10)
  EXPECT_GE(m.edits.publications, 2);
  EXPECT_GT(m.edits.last_version, 2u);

  const auto trace = read_trace(out / "trace.csv");
  const auto edits = read_csv(out / "edits.csv");
  ASSERT_EQ(edits.size(), 13u);  // carve, begin, 10 carves, end
  int at_vhip = 0;
  for (const auto& e : edits) {
    if (e.at("event") != "carve" || std::stol(e.at("tick")) < 1000) continue;
    const auto& r = trace.at(std::size_t(std::stol(e.at("tick"))));
    ASSERT_TRUE(r.contact) << "tick " << e.at("tick");
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(std::stod(e.at(std::string("centre_") + "xyz"[a] + "_mm")), r.vhip[a] * 1e3, 1e-5);
    ++at_vhip;
  }
  EXPECT_EQ(at_vhip, 10);
  // The removed volume against the edited volume read back from drilled.vdb.
  const auto after = isotouch::io::load_vdb((out / "drilled.vdb").string());
  const long removed = inside(v) - inside(after.volume);
  EXPECT_GT(removed, 20);
  EXPECT_DOUBLE_EQ(m.edits.removed_mm3, double(removed) * 1.0);  // 1 mm^3 voxels
  std::ifstream js(out / "summary.json");
  const auto j = nlohmann::json::parse(js);
  EXPECT_DOUBLE_EQ(j.at("edits").at("removed_mm3").get<double>(), double(removed));
  EXPECT_TRUE(fs::exists(out / "drilled.stl"));
  fs::remove_all(out);
}

// The shipped drill scene: the HIP ends up deeper along the press ray than the bone is thick
// there (the burr went through), the VHIP crossed the bone's middle where the bone is gone
// now, material was removed, and the files exist.
TEST(RunEdits, DrillSkullGoesThroughTheBone) {
  auto scene = isotouch::io::load_scene(kScenes + "/drill-skull.json");
  scene.draw_plots = false;  // pictures take most of the run's time on lavapipe; cli_run_drill_skull checks them
  const fs::path out = temp_dir("isotouch_edits_drill");
  isotouch::run::RunOptions opt;
  opt.out_dir = out.string();
  opt.progress = false;
  opt.record_path = (out / "run.rec").string();
  std::ostringstream log;
  const auto m = isotouch::run::run_scene(scene, opt, log);
  // The bone along the press ray, from this file's own trilinear interpolation of the
  // unedited volume: from the first point inside (the contact) to the first point outside after it.
  const Volume before = isotouch::io::load_volume(scene.volume_path);
  const auto trace = read_trace(out / "trace.csv");
  ASSERT_FALSE(trace.empty());
  // The press ray: from the contact point along the inward normal (summary.json and
  // trace.csv are in the file's physical frame; the volume's own to_grid takes them to the
  // grid frame the trilinear samples and the recording use).
  std::ifstream js(out / "summary.json");
  const auto j = nlohmann::json::parse(js);
  const auto& cpj = j.at("script").at("contact_point_m");
  const auto& nj = j.at("script").at("contact_normal");
  const Vec3 cp_phys{cpj[0].get<double>(), cpj[1].get<double>(), cpj[2].get<double>()};
  const Vec3 n_phys{nj[0].get<double>(), nj[1].get<double>(), nj[2].get<double>()};
  const Vec3 cp = before.to_grid(cp_phys);
  const Vec3 dir = (before.to_grid(cp_phys + n_phys) - cp) * -1.0;
  const Vec3 p = cp - dir * 0.005;  // 5 mm outside
  const double step = 0.05e-3;
  double entry = -1, exit = -1;
  for (double s = 0; s < 0.05; s += step) {
    const double val = trilinear(before, p + dir * s);
    if (entry < 0 && val > 1150) entry = s;
    if (entry >= 0 && val <= 1150) {
      exit = s;
      break;
    }
  }
  ASSERT_GE(entry, 0);
  ASSERT_GT(exit, entry);
  const double thickness = exit - entry;
  const Vec3 outer = p + dir * entry;
  double deepest = -1e9;
  for (const auto& r : trace)
    deepest = std::max(deepest, isotouch::core::dot(before.to_grid(Vec3{r.hip[0], r.hip[1], r.hip[2]}) - outer, dir));
  EXPECT_GT(deepest, thickness) << "bone " << thickness * 1e3 << " mm thick, HIP at most " << deepest * 1e3
                                << " mm past its outer surface";
  // Each contact tick's VHIP against the volume of the snapshot THAT tick read (not the
  // final one): the recorded edits re-applied here, on the CPU, in an EditSession of this
  // test's own, up to the version each tick recorded. The VHIP sits on that volume's
  // surface (at most a fraction of the bone's contrast inside it), never deep in bone that
  // the servo failed to render; past the bone's middle it is where the drill removed bone.
  const auto rec = isotouch::io::load_recording(opt.record_path);
  ASSERT_EQ(rec.ticks.size(), trace.size());
  ASSERT_EQ(rec.format_version, 3);
  isotouch::session::LiveFieldOptions lo;
  lo.passes = isotouch::run::scene_passes(scene);
  lo.iso = isotouch::core::Isosurface{scene.hri.tau, scene.hri.inside};
  lo.background = float(lo.iso.outside_value(before.min_value, before.max_value));
  lo.format = isotouch::run::scene_sample_format(scene);
  EditSession replica(Volume(before), nullptr, lo);
  std::size_t e = 0;
  bool crossed = false;
  double worst_excess = -1e9;
  long checked = 0, versions_seen = 0;
  for (std::size_t k = 0; k < trace.size(); ++k) {
    const auto& t = rec.ticks[k];
    ASSERT_EQ(replica.current()->version, t.version) << "tick " << k << ": the replica is not at the version the tick read";
    if (trace[k].contact) {
      const Vec3 v = t.vhip_m;
      const double value = trilinear(replica.volume(), v);
      worst_excess = std::max(worst_excess, value - scene.hri.tau);
      ++checked;
      if (isotouch::core::dot(v - outer, dir) >= 0.5 * thickness) {
        if (!crossed) {
          EXPECT_GT(trilinear(before, v), 1150) << "past the middle, the VHIP was not where bone had been";
        }
        crossed = true;
      }
    }
    const std::uint64_t v0 = replica.current()->version;
    // Format 3: an edit's tick is the number of ticks run when it was applied (k + 1 for
    // one applied after tick k), so tick k + 1 is the first that may read it.
    for (; e < rec.edits.size() && rec.edits[e].tick == long(k) + 1; ++e) replica.apply(rec.edits[e], nullptr);
    versions_seen += replica.current()->version != v0;
  }
  EXPECT_GT(checked, 500);
  EXPECT_GT(versions_seen, 10);
  // The bone is about 1150..2500 in value; a VHIP on the surface of what was felt reads tau
  // within a few percent of that contrast (measured: 4.2; trilinear of the raw voxels vs the smoothed
  // snapshot's isosurface).
  EXPECT_LT(worst_excess, 50.0) << "a VHIP sat " << worst_excess << " above the isovalue in the volume its tick read";
  std::cout << "drill-skull: " << checked << " contact ticks checked against the volume each read (" << versions_seen
            << " versions); worst VHIP excess over tau " << worst_excess << "\n";
  EXPECT_TRUE(crossed);
  EXPECT_GT(m.edits.removed_mm3, 0);
  EXPECT_GT(m.edits.button_brushes, 10);
  EXPECT_GT(m.edits.max_hip_depth_m, thickness);
  for (const char* f : {"drilled.vdb", "drilled.stl", "edits.csv", "report.md"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  fs::remove_all(out);
}
