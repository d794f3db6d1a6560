// What a program does with its edit journal at start (io/journal_offer.h), judged by the
// files left and the log: a journal of another volume is not restored and kept as
// .refused; --restore no and an answer "n" keep it as .unrestored, "y" on a terminal
// restores it; a journal held by a running session turns the journal off; and the restored
// edits, a stroke left open by the kill included, give the volume a direct application gives,
// bit for bit, with that stroke closed.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "isotouch/engine/synthetic.h"
#include "isotouch/io/journal_offer.h"
#include "isotouch/session/brush.h"

namespace fs = std::filesystem;
using isotouch::io::Journal;
using isotouch::io::open_journal;
using isotouch::io::RestoreChoice;
using isotouch::session::EditEvent;

namespace {

constexpr std::uint32_t kCrc = 0x0badf00du;

/// A state folder of its own (XDG_STATE_HOME) for each test.
fs::path state_home(const std::string& tag) {
  const fs::path d = fs::temp_directory_path() / ("isotouch_test_journal_offer_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  ::setenv("XDG_STATE_HOME", d.c_str(), 1);
  return d;
}

std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

EditEvent brush_at(double x) {
  EditEvent e;
  e.kind = EditEvent::Kind::kBrush;
  e.brush.centre_m = {x, 0, 0};
  return e;
}

/// A journal left by a killed session: header of volume `crc`, `n` brushes.
std::string leave_journal(const std::string& program, std::uint32_t key_crc, std::uint32_t crc, int n) {
  const std::string path = isotouch::io::journal_path(isotouch::io::journal_dir(), program, key_crc);
  Journal j(path);
  isotouch::io::Recording h;
  h.rate_hz = 1000;
  h.volume_crc32 = crc;
  std::vector<EditEvent> edits;
  for (int i = 0; i < n; ++i) edits.push_back(brush_at(0.001 * i));
  j.start(h, edits);
  return path;  // not closed: kept, as after a kill
}

}  // namespace

TEST(JournalOffer, AnotherVolumesJournalIsNotRestoredAndKeptAsRefused) {
  state_home("refused");
  const std::string path = leave_journal("p", kCrc, 0x11111111u, 2);
  const std::string before = read(path);
  std::ostringstream log;
  std::istringstream none;
  const auto opened = open_journal("p", kCrc, RestoreChoice::kYes, log, none, false);
  ASSERT_TRUE(opened.journal);
  EXPECT_TRUE(opened.restore.empty());
  EXPECT_NE(log.str().find("of another volume (11111111, this one is 0badf00d)"), std::string::npos) << log.str();
  EXPECT_EQ(read(path + ".refused"), before);
}

TEST(JournalOffer, NoKeepsTheJournalAsUnrestored) {
  state_home("no");
  const std::string path = leave_journal("p", kCrc, kCrc, 3);
  const std::string before = read(path);
  std::ostringstream log;
  std::istringstream none;
  const auto opened = open_journal("p", kCrc, RestoreChoice::kNo, log, none, false);
  EXPECT_TRUE(opened.restore.empty());
  EXPECT_NE(log.str().find("journal  restore 3 edits from "), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("not restored (--restore no)"), std::string::npos) << log.str();
  EXPECT_EQ(read(path + ".unrestored"), before);
}

// A second journal not restored is kept beside the first, which is never overwritten.
TEST(JournalOffer, ASecondUnrestoredJournalDoesNotReplaceTheFirst) {
  state_home("no_twice");
  std::ostringstream log;
  std::istringstream none;
  const std::string path = leave_journal("p", kCrc, kCrc, 3);
  const std::string first = read(path);
  (void)open_journal("p", kCrc, RestoreChoice::kNo, log, none, false);
  leave_journal("p", kCrc, kCrc, 5);
  const std::string second = read(path);
  ASSERT_NE(first, second);
  (void)open_journal("p", kCrc, RestoreChoice::kNo, log, none, false);
  EXPECT_EQ(read(path + ".unrestored"), first) << log.str();
  EXPECT_EQ(read(path + ".unrestored.2"), second) << log.str();
}

TEST(JournalOffer, TheTerminalsAnswerDecides) {
  state_home("ask");
  leave_journal("p", kCrc, kCrc, 2);
  {
    std::ostringstream log;
    std::istringstream yes("y\n");
    const auto opened = open_journal("p", kCrc, RestoreChoice::kAsk, log, yes, true);
    ASSERT_EQ(opened.restore.size(), 2u);
    EXPECT_EQ(opened.restore[1].brush.centre_m.x, 0.001);
    EXPECT_NE(log.str().find("restore 2 edits from "), std::string::npos);
    EXPECT_NE(log.str().find("? [y/N] "), std::string::npos) << log.str();
  }
  std::ostringstream log;
  std::istringstream no("n\n");
  EXPECT_TRUE(open_journal("p", kCrc, RestoreChoice::kAsk, log, no, true).restore.empty());  // still there: not started
  EXPECT_NE(log.str().find("not restored (answered no)"), std::string::npos) << log.str();
}

TEST(JournalOffer, AJournalHeldByARunningSessionIsOff) {
  state_home("held");
  Journal running(isotouch::io::journal_path(isotouch::io::journal_dir(), "p", kCrc));
  std::ostringstream log;
  std::istringstream none;
  EXPECT_FALSE(open_journal("p", kCrc, RestoreChoice::kYes, log, none, false).journal);
  EXPECT_EQ(log.str().rfind("journal  off: ", 0), 0u) << log.str();
}

TEST(JournalOffer, RestoredEditsGiveTheVolumeBitForBitAndCloseAnOpenStroke) {
  namespace s = isotouch::session;
  const isotouch::engine::Volume v = isotouch::engine::make_sphere({24, 24, 24}, 1e-3, 8.0);
  const s::LiveFieldOptions opts{{isotouch::engine::PassDesc::gradient()},
                                 isotouch::core::Isosurface{0.0, isotouch::core::InsideIs::kAbove}, -100.f,
                                 isotouch::core::SampleFormat::kFp32};
  std::vector<EditEvent> journal;
  auto add = [&](EditEvent::Kind k, double x = 0) {
    EditEvent e = k == EditEvent::Kind::kBrush ? brush_at(x) : EditEvent{};
    e.kind = k;
    if (k == EditEvent::Kind::kBrush) {
      e.brush.kind = s::BrushKind::kCarve;
      e.brush.centre_m = v.grid.centre_m() + isotouch::core::Vec3{x, 0, 0.008};
      e.brush.radius_m = 3e-3;
      e.brush.strength = 2000;
      e.brush.targets = s::default_targets(v, opts.iso);
    }
    journal.push_back(e);
  };
  add(EditEvent::Kind::kBeginStroke), add(EditEvent::Kind::kBrush, 0), add(EditEvent::Kind::kEndStroke);
  add(EditEvent::Kind::kBeginStroke), add(EditEvent::Kind::kBrush, 0.004), add(EditEvent::Kind::kEndStroke);
  add(EditEvent::Kind::kUndo), add(EditEvent::Kind::kBeginStroke), add(EditEvent::Kind::kBrush, -0.004);  // killed here
  s::EditSession direct(isotouch::engine::Volume(v), nullptr, opts);
  for (const EditEvent& e : journal) direct.apply(e, nullptr);
  s::EditSession restored(isotouch::engine::Volume(v), nullptr, opts);
  std::vector<EditEvent> edits = journal;
  isotouch::io::apply_restored(restored, edits, nullptr);
  ASSERT_EQ(restored.volume().voxels.size(), direct.volume().voxels.size());
  EXPECT_EQ(std::memcmp(restored.volume().voxels.data(), direct.volume().voxels.data(),
                        direct.volume().voxels.size() * sizeof(float)),
            0);
  EXPECT_NE(std::memcmp(restored.volume().voxels.data(), v.voxels.data(), v.voxels.size() * sizeof(float)), 0);
  EXPECT_FALSE(restored.sculptor().history().stroke_open());
  ASSERT_EQ(edits.size(), journal.size() + 1);
  EXPECT_EQ(edits.back().kind, EditEvent::Kind::kEndStroke);  // in the new journal too
  EXPECT_EQ(restored.sculptor().history().undo_depth(), 2u);  // the first stroke and the one closed
}
