// Undo / redo: per-stroke brick backups restore the volume bit for bit
// in both directions (CPU Sculptor and GPU Sculptor, whose device copy must follow), a
// brick touched twice in a stroke keeps its first backup, a new stroke after undo drops
// the redo branch, the memory limit drops the oldest strokes; validation layer on.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <tuple>

#include "isotouch/tests/vk_test_context.h"
#include "isotouch/session/brush.h"
#include "isotouch/session/edit_history.h"
#include "isotouch/engine/synthetic.h"
#include "isotouch/io/volume_io.h"

using namespace isotouch;
using session::Brush;
using session::BrushKind;
using engine::Volume;

namespace {
const std::string kHead = std::string(ISOTOUCH_TEST_DATA) + "/ct-head-headsq/headsq_64x64x93_int16.mhd";

engine::VulkanContext& vk() { return test::validated_vk(); }

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

Brush brush(BrushKind k, core::Vec3 c, double r, const session::BrushTargets& t) {
  Brush b;
  b.kind = k;
  b.centre_m = c;
  b.radius_m = r;
  b.targets = t;
  b.strength = k == BrushKind::kSmooth ? 0.9 : 300.0;
  b.force_n = 4;
  b.rate = 1e5;
  return b;
}

TEST(BrickIo, ReadWriteRoundTripAndClippedBricks) {
  Volume v = engine::make_random({19, 10, 9}, {1e-3, 1e-3, 1e-3}, 0.0f, 1.0f, 5);
  EXPECT_EQ(session::brick_total(v.grid), 3u * 2u * 2u);
  const auto box = session::brick_box(v.grid, 11);  // (2, 1, 1): x 16..19, y 8..10, z 8..9
  EXPECT_EQ(box.voxels(), 3u * 2u * 1u);
  const auto d = session::read_brick(v, 11);
  EXPECT_EQ(d[0], v.voxels[v.grid.index(16, 8, 8)]);
  EXPECT_EQ(d[5], v.voxels[v.grid.index(18, 9, 8)]);
  std::vector<float> z(d.size(), -7.0f);
  Volume w = v;
  session::write_brick(w, 11, z.data());
  EXPECT_EQ(w.voxels[v.grid.index(18, 9, 8)], -7.0f);
  EXPECT_EQ(w.voxels[v.grid.index(15, 9, 8)], v.voxels[v.grid.index(15, 9, 8)]);
  EXPECT_THROW(session::brick_box(v.grid, 12), std::out_of_range);
}

/// Strokes of every kind, overlapping; undo all restores the original, redo all the
/// edited volume, both bit for bit; on the GPU path the device copy follows.
void undo_redo_roundtrip(engine::VulkanContext* ctx) {
  Volume v0 = io::load_volume(kHead);
  const auto t = session::default_targets(v0, {1150.0, core::InsideIs::kAbove});
  session::Sculptor s(v0, ctx, 64.0);
  s.set_cpu_max_bricks(0);  // with a device: every brush there (the device path's test)
  const core::Vec3 c = v0.grid.centre_m();
  std::vector<std::vector<float>> states{v0.voxels};
  const BrushKind kinds[] = {BrushKind::kCarve, BrushKind::kAdd, BrushKind::kSmooth, BrushKind::kDrill};
  for (int k = 0; k < 4; ++k) {
    s.begin_stroke();
    for (int step = 0; step < 5; ++step)  // a stroke: a short drag, bricks touched repeatedly
      s.apply(brush(kinds[k], c + core::Vec3{0.004 * step, 0.002 * k, 0.001 * step}, 9e-3, t));
    s.end_stroke();
    states.push_back(s.volume().voxels);
    ASSERT_FALSE(same_bits(states[states.size() - 1], states[states.size() - 2]));
  }
  EXPECT_EQ(s.history().undo_depth(), 4u);
  for (int k = 3; k >= 0; --k) {
    const auto ids = s.undo();
    EXPECT_FALSE(ids.empty());
    ASSERT_TRUE(same_bits(s.volume().voxels, states[std::size_t(k)])) << "undo to state " << k;
    if (s.engine()) {
      ASSERT_TRUE(same_bits(s.engine()->download_all(), states[std::size_t(k)])) << "device copy";
    }
  }
  EXPECT_TRUE(s.undo().empty());  // nothing left
  for (int k = 1; k <= 4; ++k) {
    s.redo();
    ASSERT_TRUE(same_bits(s.volume().voxels, states[std::size_t(k)])) << "redo to state " << k;
    if (s.engine()) {
      ASSERT_TRUE(same_bits(s.engine()->download_all(), states[std::size_t(k)])) << "device copy";
    }
  }
  EXPECT_TRUE(s.redo().empty());
  // Undo twice, redo once, then a new stroke: the redo branch is gone.
  s.undo();
  s.undo();
  s.redo();
  s.apply(brush(BrushKind::kCarve, c, 5e-3, t));
  EXPECT_EQ(s.history().redo_depth(), 0u);
  EXPECT_TRUE(s.redo().empty());
  s.undo();
  ASSERT_TRUE(same_bits(s.volume().voxels, states[3]));
}

TEST(EditHistory, UndoRedoBitForBitCpu) { undo_redo_roundtrip(nullptr); }

TEST(EditHistory, UndoRedoBitForBitGpu) {
  undo_redo_roundtrip(&vk());
  EXPECT_EQ(vk().validation_messages(), 0u) << "the validation layer reported messages (see stderr)";
}

TEST(EditHistory, BrickTouchedTwiceKeepsItsFirstBackup) {
  Volume v0 = engine::make_random({24, 24, 24}, {1e-3, 1e-3, 1e-3}, 0.0f, 100.0f, 9);
  session::EditHistory h(16.0);
  Volume v = v0;
  Brush b = brush(BrushKind::kAdd, v.grid.centre_m(), 5e-3, {1000.0f, 0.0f, 1000.0f});
  b.strength = 10;
  h.begin_stroke();
  for (int k = 0; k < 3; ++k) {  // the same bricks, three times
    h.record(v, session::touched_bricks(v.grid, b));
    session::apply_brush_cpu(v, b);
  }
  h.end_stroke(v);
  std::vector<std::uint32_t> hooked;
  h.set_on_restore([&](const std::vector<std::uint32_t>& ids) { hooked = ids; });
  const auto ids = h.undo(v);
  EXPECT_TRUE(same_bits(v.voxels, v0.voxels)) << "undo must restore the pre-stroke content";
  EXPECT_EQ(hooked, ids);
  EXPECT_FALSE(ids.empty());
}

// A hook that throws (a GPU copy that cannot take the bricks) fails the undo or redo as a
// whole: the volume, the undo and the redo stacks are as they were, and the next try works.
TEST(EditHistory, AnUndoOrRedoWhoseHookThrowsChangesNothing) {
  const Volume v0 = engine::make_random({24, 24, 24}, {1e-3, 1e-3, 1e-3}, 0.0f, 100.0f, 9);
  session::EditHistory h(16.0);
  Volume v = v0;
  Brush b = brush(BrushKind::kAdd, v.grid.centre_m(), 5e-3, {1000.0f, 0.0f, 1000.0f});
  h.begin_stroke();
  h.record(v, session::touched_bricks(v.grid, b));
  session::apply_brush_cpu(v, b);
  h.end_stroke(v);
  const Volume v1 = v;
  int fail = 0;  // calls of the hook that throw
  h.set_on_restore([&](const std::vector<std::uint32_t>&) {
    if (fail-- > 0) throw std::runtime_error("device lost");
  });
  // Each step fails once (nothing changes), then works: (undo, before, after, depths).
  const bool undo = true, redo = false;
  for (const auto& [step, before, after] : {std::tuple{undo, &v1, &v0}, std::tuple{redo, &v0, &v1}}) {
    const auto run = [&, step = step] { return step ? h.undo(v) : h.redo(v); };
    const std::size_t undo_depth = h.undo_depth(), redo_depth = h.redo_depth();
    fail = 1;
    EXPECT_THROW(run(), std::runtime_error);
    EXPECT_TRUE(same_bits(v.voxels, before->voxels)) << (step ? "undo" : "redo") << " that failed changed the volume";
    EXPECT_EQ(h.undo_depth(), undo_depth);
    EXPECT_EQ(h.redo_depth(), redo_depth);
    EXPECT_FALSE(run().empty());
    EXPECT_TRUE(same_bits(v.voxels, after->voxels));
  }
}

TEST(EditHistory, UnchangedBricksAreNotKept) {
  Volume v = engine::make_linear({32, 32, 32}, {1e-3, 1e-3, 1e-3}, {0, 0, 0}, 0.0);
  session::EditHistory h(16.0);
  Brush b = brush(BrushKind::kCarve, v.grid.centre_m(), 6e-3, {1000.0f, 0.0f, 1000.0f});  // already empty
  h.begin_stroke();
  h.record(v, session::touched_bricks(v.grid, b));
  EXPECT_GT(h.bytes(), 0u);
  session::apply_brush_cpu(v, b);
  h.end_stroke(v);
  EXPECT_EQ(h.bytes(), 0u);
  EXPECT_EQ(h.undo_depth(), 0u);
}

TEST(EditHistory, MemoryLimitDropsTheOldestStrokes) {
  Volume v0 = engine::make_random({64, 64, 16}, {1e-3, 1e-3, 1e-3}, 0.0f, 100.0f, 2);
  // Each stroke: one brick-centred brush of radius 3 mm touches one brick column (8^3 floats =
  // 2 KiB per brick); limit 0.01 MiB = 10485 bytes = at most 5 full bricks.
  session::Sculptor s(v0, nullptr, 0.01);
  const session::BrushTargets t{1000.0f, 0.0f, 1000.0f};
  std::vector<std::vector<float>> states{v0.voxels};
  for (int k = 0; k < 6; ++k) {
    s.apply(brush(BrushKind::kAdd, v0.grid.to_world({8.0 * k + 3.5, 3.5, 3.5}), 2e-3, t));
    states.push_back(s.volume().voxels);
    EXPECT_LE(s.history().bytes(), s.history().limit_bytes());
  }
  EXPECT_EQ(s.history().limit_bytes(), std::uint64_t(0.01 * 1048576.0));
  EXPECT_EQ(s.history().dropped_strokes(), 1u);  // 6 strokes of 2048 B: 12288 > 10485, the first goes
  EXPECT_EQ(s.history().undo_depth(), 5u);
  EXPECT_EQ(s.history().bytes(), 5u * 2048u);
  while (!s.undo().empty()) {
  }
  EXPECT_TRUE(same_bits(s.volume().voxels, states[1])) << "undo stops after the oldest kept stroke";
  EXPECT_THROW(session::EditHistory(-1.0), std::invalid_argument);
}

TEST(EditHistory, AStrokeLargerThanTheLimitIsABarrier) {
  // Stroke A backs up brick X; stroke B changes X and many more bricks and is too large to
  // keep. Undoing A then would put X back under B's changes: a state that never existed.
  // B is a barrier: A goes with it, undo stops at B, strokes after B undo as usual.
  Volume v0 = engine::make_random({64, 64, 16}, {1e-3, 1e-3, 1e-3}, 0.0f, 100.0f, 2);
  session::Sculptor s(v0, nullptr, 0.01);  // 10485 bytes: 5 bricks
  const session::BrushTargets t{1000.0f, 0.0f, 1000.0f};
  s.apply(brush(BrushKind::kAdd, v0.grid.to_world({27.5, 27.5, 7.5}), 2e-3, t));  // A: inside B's reach
  s.apply(brush(BrushKind::kAdd, v0.grid.to_world({11.5, 3.5, 3.5}), 2e-3, t));
  ASSERT_EQ(s.history().undo_depth(), 2u);
  // B: radius 10 mm around the centre, about 32 bricks (64 KiB), far over the limit.
  s.apply(brush(BrushKind::kCarve, v0.grid.to_world({32.0, 32.0, 8.0}), 10e-3, t));
  const std::vector<float> after_b = s.volume().voxels;
  EXPECT_EQ(s.history().dropped_strokes(), 3u) << "B and the two strokes before it";
  EXPECT_EQ(s.history().undo_depth(), 0u);
  EXPECT_EQ(s.history().bytes(), 0u);
  EXPECT_TRUE(s.undo().empty()) << "nothing to undo past the barrier";
  EXPECT_TRUE(same_bits(s.volume().voxels, after_b)) << "an undo past the barrier changed the volume";
  // C after the barrier: undone back to exactly the state after B.
  s.apply(brush(BrushKind::kAdd, v0.grid.to_world({3.5, 60.5, 3.5}), 2e-3, t));
  EXPECT_EQ(s.history().undo_depth(), 1u);
  EXPECT_FALSE(s.undo().empty());
  EXPECT_TRUE(same_bits(s.volume().voxels, after_b));
}

}  // namespace

// clear(): undo and redo strokes and what the open stroke recorded are gone (counted as
// dropped, no payload held), the open stroke stays open under a new serial, and a stroke
// recorded after it undoes only itself; record() from a buffer takes the buffer's content,
// not the volume's. Truth: the volumes written before, bit for bit.
TEST(EditHistory, ClearDropsEveryStrokeAndKeepsTheOpenOneOpen) {
  Volume v = engine::make_random({19, 10, 9}, {1e-3, 1e-3, 1e-3}, 0.0f, 1.0f, 5);
  const std::vector<float> v0 = v.voxels;
  session::EditHistory h(16.0);
  auto stroke = [&](std::uint32_t id, float value) {  // brick `id` set to `value`, one stroke
    h.begin_stroke();
    h.record(v, {id});
    std::vector<float> d(session::brick_box(v.grid, id).voxels(), value);
    session::write_brick(v, id, d.data());
    h.end_stroke(v);
  };
  stroke(0, 5.f);
  stroke(1, 6.f);
  stroke(2, 7.f);
  ASSERT_FALSE(h.undo(v).empty());  // one redo stroke
  ASSERT_EQ(h.undo_depth(), 2u);
  ASSERT_EQ(h.redo_depth(), 1u);
  h.begin_stroke();
  const std::uint64_t serial = h.open_stroke_serial();
  h.record(v, {3});
  ASSERT_GT(h.bytes(), 0u);
  const std::size_t dropped = h.dropped_strokes();
  h.clear();
  EXPECT_EQ(h.undo_depth(), 0u);
  EXPECT_EQ(h.redo_depth(), 0u);
  EXPECT_EQ(h.bytes(), 0u);
  EXPECT_EQ(h.dropped_strokes(), dropped + 2u + 1u);  // two undo strokes and the open one (begin_stroke set the redo branch aside)
  ASSERT_TRUE(h.stroke_open());
  EXPECT_GT(h.open_stroke_serial(), serial);
  // The open stroke goes on: brick 4 recorded from a buffer (its old content), then changed.
  const std::vector<float> before = v.voxels;
  std::vector<float> d(session::brick_box(v.grid, 4).voxels(), 9.f);
  session::write_brick(v, 4, d.data());
  h.record(v.grid, before.data(), {4});
  h.end_stroke(v);
  EXPECT_EQ(h.undo_depth(), 1u);
  EXPECT_FALSE(h.undo(v).empty());
  EXPECT_TRUE(same_bits(v.voxels, before));
  EXPECT_TRUE(h.undo(v).empty());
  EXPECT_FALSE(same_bits(v.voxels, v0));  // bricks 0 and 1 stay as the dropped strokes left them
}
