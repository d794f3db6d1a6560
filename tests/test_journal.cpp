// The edit journal (io/journal.h), judged by what its file holds: the edits appended are
// in the file (read back by the recording parser) after flush() and within a second
// without it; a file cut mid-record by a kill gives back every whole record and the bytes
// dropped; a journal of another volume is refused naming both CRCs; a journal held by a
// running session is refused; close() deletes the file, an unclean end keeps it.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "isotouch/io/journal.h"

namespace fs = std::filesystem;
using isotouch::io::Journal;
using isotouch::io::JournalError;
using isotouch::io::Recording;
using isotouch::session::EditEvent;

namespace {

constexpr std::uint32_t kCrc = 0x1234abcdu;

fs::path temp_file(const std::string& tag) {
  const fs::path d = fs::temp_directory_path() / ("isotouch_test_journal_" + std::to_string(::getpid()));
  fs::create_directories(d);
  const fs::path p = d / (tag + ".journal");
  fs::remove(p);
  return p;
}

std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

Recording header(std::uint32_t crc = kCrc) {
  Recording r;
  r.scene_path = "/data/head.mha";
  r.rate_hz = 1000;
  r.volume_crc32 = crc;
  return r;
}

EditEvent brush_at(double x, long tick) {
  EditEvent e;
  e.kind = EditEvent::Kind::kBrush;
  e.tick = tick;
  e.t_s = 0.001 * double(tick);
  e.brush.centre_m = {x, 0.25, -0.125};
  e.brush.radius_m = 0.004;
  return e;
}

EditEvent event(EditEvent::Kind k, long tick) {
  EditEvent e;
  e.kind = k;
  e.tick = tick;
  return e;
}

/// The file as the recording parser reads it (a journal is a recording without ticks).
Recording parsed(const fs::path& p) { return isotouch::io::parse_recording(read(p), p.string(), true); }

}  // namespace

TEST(Journal, FlushPutsEveryAppendedEditInTheFile) {
  const fs::path p = temp_file("flush");
  Journal j(p.string());
  j.start(header(), {});
  j.append(event(EditEvent::Kind::kBeginStroke, 3));
  j.append(brush_at(0.01, 4));
  j.append(event(EditEvent::Kind::kEndStroke, 5));
  j.append(event(EditEvent::Kind::kUndo, 9));
  j.flush();
  const Recording r = parsed(p);
  ASSERT_EQ(r.volume_crc32, kCrc);
  ASSERT_EQ(r.edits.size(), 4u);
  EXPECT_EQ(r.edits[0].kind, EditEvent::Kind::kBeginStroke);
  EXPECT_EQ(r.edits[1].kind, EditEvent::Kind::kBrush);
  EXPECT_EQ(r.edits[1].brush.centre_m.x, 0.01);
  EXPECT_EQ(r.edits[1].brush.radius_m, 0.004);
  EXPECT_EQ(r.edits[3].kind, EditEvent::Kind::kUndo);
  EXPECT_EQ(j.edits(), 4);
}

TEST(Journal, AnAppendedEditIsInTheFileWithinASecond) {
  const fs::path p = temp_file("second");
  Journal j(p.string());
  j.start(header(), {});
  j.append(brush_at(0.02, 1));
  std::this_thread::sleep_for(std::chrono::seconds(1));  // the bound the journal promises
  const Recording r = parsed(p);  // no flush(), no close(): what a kill -9 now would leave
  ASSERT_EQ(r.edits.size(), 1u);
  EXPECT_EQ(r.edits[0].brush.centre_m.x, 0.02);
}

TEST(Journal, RestoredEditsStartTheNewJournal) {
  const fs::path p = temp_file("restored");
  Journal j(p.string());
  j.start(header(), {brush_at(0.03, 700), event(EditEvent::Kind::kRedo, 800)});
  j.append(brush_at(0.04, 2));
  j.flush();
  const Recording r = parsed(p);
  ASSERT_EQ(r.edits.size(), 3u);
  EXPECT_EQ(r.edits[0].brush.centre_m.x, 0.03);
  EXPECT_EQ(r.edits[0].tick, 0);  // before this session's first tick
  EXPECT_EQ(r.edits[1].kind, EditEvent::Kind::kRedo);
  EXPECT_EQ(r.edits[2].brush.centre_m.x, 0.04);
}

TEST(Journal, ATornTailGivesBackEveryWholeRecordAndTheBytesDropped) {
  const fs::path p = temp_file("torn");
  {
    Journal j(p.string());
    j.start(header(), {});
    for (int i = 0; i < 3; ++i) j.append(brush_at(0.01 * (i + 1), i));
  }  // not closed: the file stays, as after a crash
  const std::string whole = read(p);
  const std::size_t last_line = whole.size() - (whole.rfind('\n', whole.size() - 2) + 1);  // with its newline
  fs::resize_file(p, whole.size() - 10);  // the kill cut the last record's write
  Journal again(p.string());
  const auto left = again.left(kCrc);
  ASSERT_TRUE(left.has_value());
  ASSERT_EQ(left->edits.size(), 2u);
  EXPECT_EQ(left->edits[1].brush.centre_m.x, 0.02);
  EXPECT_EQ(left->dropped_bytes, last_line - 10);
  EXPECT_EQ(left->input, "/data/head.mha");
  const std::string q = isotouch::io::restore_question(*left);
  EXPECT_EQ(q.rfind("restore 2 edits from ", 0), 0u) << q;
  EXPECT_NE(q.find(std::to_string(last_line - 10) + " bytes dropped"), std::string::npos) << q;
}

TEST(Journal, StartReplacesWhatTheLastSessionLeft) {
  const fs::path p = temp_file("replaced");
  { Journal(p.string()).start(header(), {brush_at(0.01, 1), brush_at(0.02, 2)}); }
  Journal again(p.string());
  ASSERT_EQ(again.left(kCrc)->edits.size(), 2u);
  again.start(header(), {});  // not restored: this session's journal starts empty
  again.append(brush_at(0.05, 1));
  again.flush();
  const Recording r = parsed(p);
  ASSERT_EQ(r.edits.size(), 1u);
  EXPECT_EQ(r.edits[0].brush.centre_m.x, 0.05);
}

// serve's `isovalue V`: the running journal goes on for the rebuilt session, its file
// replaced with the edits kept and the new header, and no other session can take the file
// at any point (its lock held throughout); appends after it follow the kept edits.
TEST(Journal, RestartReplacesTheFileAndKeepsItsLock) {
  const fs::path p = temp_file("restart");
  Journal j(p.string());
  j.start(header(), {});
  j.append(brush_at(0.01, 1));
  j.append(brush_at(0.02, 2));
  Recording after = header();
  after.isovalue = isotouch::core::Isosurface{-500, isotouch::core::InsideIs::kAbove};
  j.restart(after, {brush_at(0.01, 1), brush_at(0.02, 2)});
  EXPECT_THROW(Journal(p.string()), JournalError);  // still held
  j.append(brush_at(0.03, 3));
  j.flush();
  const Recording r = parsed(p);
  ASSERT_TRUE(r.isovalue.has_value());
  EXPECT_EQ(r.isovalue->tau, -500);
  ASSERT_EQ(r.edits.size(), 3u);
  EXPECT_EQ(r.edits[0].tick, 0);  // kept: before the rebuilt session's first tick
  EXPECT_EQ(r.edits[2].brush.centre_m.x, 0.03);
  EXPECT_FALSE(fs::exists(p.string() + ".new"));
  j.close();
  EXPECT_FALSE(fs::exists(p));
}

// A rewrite that fails (here its file cannot be made: a folder stands in its place) leaves
// the file as it was and locked, and nothing is written to it after: serve moves it aside.
TEST(Journal, AFailedRestartLeavesTheFileAsItWasLockedAndWritesNothingMore) {
  const fs::path p = temp_file("restart_fails");
  const fs::path blocker = p.string() + ".new";
  fs::remove_all(blocker);
  std::string before;
  {
    Journal j(p.string());
    j.start(header(), {});
    j.append(brush_at(0.01, 1));
    j.flush();
    before = read(p);
    fs::create_directory(blocker);
    EXPECT_THROW(j.restart(header(), {brush_at(0.01, 1)}), JournalError);
    EXPECT_EQ(read(p), before);
    EXPECT_THROW(Journal(p.string()), JournalError);  // still held: no other session took it
    j.append(brush_at(0.02, 2));
    EXPECT_THROW(j.flush(), JournalError);
    EXPECT_EQ(read(p), before);
  }
  EXPECT_EQ(read(p), before);  // kept (not closed): the next start would offer it, serve moves it aside
  fs::remove_all(blocker);
}

TEST(Journal, AJournalOfAnotherVolumeIsRefusedNamingBoth) {
  const fs::path p = temp_file("other");
  { Journal(p.string()).start(header(0x00c0ffeeu), {brush_at(0.01, 1)}); }
  Journal again(p.string());
  try {
    (void)again.left(kCrc);
    FAIL() << "a journal of another volume was accepted";
  } catch (const JournalError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(p.string()), std::string::npos) << what;
    EXPECT_NE(what.find("00c0ffee"), std::string::npos) << what;
    EXPECT_NE(what.find("1234abcd"), std::string::npos) << what;
  }
}

TEST(Journal, AJournalHeldByARunningSessionIsRefused) {
  const fs::path p = temp_file("held");
  Journal first(p.string());
  try {
    Journal second(p.string());
    FAIL() << "two sessions share one journal";
  } catch (const JournalError& e) {
    EXPECT_NE(std::string(e.what()).find("held by another running session"), std::string::npos) << e.what();
  }
}

TEST(Journal, CloseDeletesTheFileAndAnEmptyJournalLeavesNothing) {
  const fs::path p = temp_file("close");
  {
    Journal j(p.string());
    EXPECT_FALSE(j.left(kCrc).has_value());  // new: nothing left
    j.start(header(), {});
    j.append(brush_at(0.01, 1));
    j.close();
  }
  EXPECT_FALSE(fs::exists(p));
}

TEST(Journal, TheFolderIsTheXdgStateHome) {
  ::setenv("XDG_STATE_HOME", "/tmp/state-x", 1);
  EXPECT_EQ(isotouch::io::journal_dir(), "/tmp/state-x/isotouch");
  ::unsetenv("XDG_STATE_HOME");
  ::setenv("HOME", "/home/u", 1);
  EXPECT_EQ(isotouch::io::journal_dir(), "/home/u/.local/state/isotouch");
  EXPECT_EQ(isotouch::io::journal_path("/d", "sculpt", 0xabcu), "/d/sculpt-00000abc.journal");
}
