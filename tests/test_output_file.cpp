// The one output writer: a regular file or nothing is replaced atomically, a character
// device, FIFO or "-" written in place as a stream, a symlink followed, anything else refused.
// Truth: stat(2) of the targets before and after, and the bytes read back.
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <future>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "isotouch/tests/temp_dir.h"

#include "isotouch/io/output_file.h"

namespace fs = std::filesystem;
using isotouch::test::slurp;
using TempDir = isotouch::test::TempDir;
using isotouch::io::OutputError;
using isotouch::io::OutputKind;
using isotouch::io::classify_output;
using isotouch::io::place_output;
using isotouch::io::write_output;

namespace {



bool is_char_device(const fs::path& p) {
  struct stat st {};
  return ::lstat(p.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
}

/// A character device node like /dev/null (1, 3) made in `dir`; "" when mknod is not allowed.
fs::path make_null_device(const fs::path& dir) {
  const fs::path p = dir / "null-device";
  if (::mknod(p.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0) return {};
  return p;
}

/// Files in `dir` whose name holds ".tmp-": a temp file left behind.
int leftovers(const fs::path& dir) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos) ++n;
  return n;
}

}  // namespace

TEST(OutputFile, NewAndRegularFilesAreReplacedWhole) {
  TempDir d;
  const fs::path p = d.path / "sub" / "out.json";
  try {
    write_output(p.string(), std::string_view("first"));
    FAIL() << "a missing folder must be an error";
  } catch (const OutputError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
  fs::create_directories(p.parent_path());
  write_output(p.string(), std::string_view("first"));
  EXPECT_EQ(slurp(p), "first");
  struct stat first {};
  ASSERT_EQ(::stat(p.c_str(), &first), 0);
  write_output(p.string(), std::string_view("second, longer"));
  EXPECT_EQ(slurp(p), "second, longer");
  struct stat st {};
  ASSERT_EQ(::stat(p.c_str(), &st), 0);
  EXPECT_NE(st.st_ino, first.st_ino) << "the file must be replaced by rename, not rewritten in place";
  EXPECT_EQ(leftovers(p.parent_path()), 0);
}

TEST(OutputFile, AFailingFillLeavesTheOldFileAndNoTemp) {
  TempDir d;
  const fs::path p = d.path / "out.csv";
  write_output(p.string(), std::string_view("old"));
  EXPECT_THROW(write_output(p.string(), [](const std::string& f) {
                 std::ofstream(f) << "half";
                 throw std::runtime_error("writer failed");
               }),
               std::runtime_error);
  EXPECT_EQ(slurp(p), "old");
  EXPECT_EQ(leftovers(d.path), 0);
}

TEST(OutputFile, CharacterDeviceIsWrittenInPlaceNotReplaced) {
  TempDir d;
  const fs::path dev = make_null_device(d.path);
  if (dev.empty()) GTEST_SKIP() << "mknod not permitted here (needs root)";
  EXPECT_EQ(classify_output(dev.string()).kind, OutputKind::kStream);
  write_output(dev.string(), std::string_view("bytes for the device"));
  EXPECT_TRUE(is_char_device(dev)) << "the device node was replaced by a regular file";
  write_output(dev.string(), [](const std::string& f) { std::ofstream(f) << "through a fill"; });
  EXPECT_TRUE(is_char_device(dev));
  EXPECT_EQ(leftovers(d.path), 0);
}

TEST(OutputFile, FullDeviceReportsTheWriteError) {
  // /dev/full: every write fails with ENOSPC; the error names the path and the node stays.
  TempDir d;
  const fs::path full = d.path / "full-device";
  if (::mknod(full.c_str(), S_IFCHR | 0666, makedev(1, 7)) != 0) GTEST_SKIP() << "mknod not permitted here";
  try {
    write_output(full.string(), std::string_view("x"));
    FAIL() << "a write to a full device must fail";
  } catch (const OutputError& e) {
    EXPECT_NE(std::string(e.what()).find(full.string()), std::string::npos) << e.what();
  }
  EXPECT_TRUE(is_char_device(full));
}

TEST(OutputFile, FifoIsWrittenAsAStream) {
  TempDir d;
  const fs::path fifo = d.path / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto reader = std::async(std::launch::async, [&] { return slurp(fifo); });
  write_output(fifo.string(), std::string_view("through the pipe"));
  EXPECT_EQ(reader.get(), "through the pipe");
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced";
}

TEST(OutputFile, SymlinkToAFileReplacesTheTargetAndKeepsTheLink) {
  TempDir d;
  fs::create_directories(d.path / "real");
  const fs::path target = d.path / "real" / "summary.json";
  std::ofstream(target) << "old";
  const fs::path link = d.path / "link.json";
  fs::create_symlink("real/summary.json", link);  // relative, against the link's folder
  write_output(link.string(), std::string_view("new"));
  EXPECT_TRUE(fs::is_symlink(link)) << "the symlink was replaced by a file";
  EXPECT_EQ(slurp(target), "new");
  EXPECT_EQ(leftovers(d.path), 0);
  EXPECT_EQ(leftovers(d.path / "real"), 0);
}

TEST(OutputFile, DanglingSymlinkCreatesItsTarget) {
  TempDir d;
  const fs::path link = d.path / "link.csv";
  fs::create_directories(d.path / "made");
  fs::create_symlink(d.path / "made" / "by-write.csv", link);
  write_output(link.string(), std::string_view("made"));
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(slurp(d.path / "made" / "by-write.csv"), "made");
}

TEST(OutputFile, SymlinkToADeviceWritesTheDevice) {
  TempDir d;
  const fs::path dev = make_null_device(d.path);
  if (dev.empty()) GTEST_SKIP() << "mknod not permitted here (needs root)";
  const fs::path link = d.path / "out.png";
  fs::create_symlink(dev, link);
  write_output(link.string(), std::string_view("png bytes"));
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_TRUE(is_char_device(dev));
}

TEST(OutputFile, DirectoryLoopAndEmptyAreRefusedNamingThePath) {
  TempDir d;
  const fs::path dir = d.path / "a-folder";
  fs::create_directories(dir);
  try {
    write_output(dir.string(), std::string_view("x"));
    FAIL() << "a directory must be refused";
  } catch (const OutputError& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find(dir.string()), std::string::npos) << w;
    EXPECT_NE(w.find("directory"), std::string::npos) << w;
  }
  EXPECT_TRUE(fs::is_directory(dir));
  const fs::path a = d.path / "loop-a", b = d.path / "loop-b";
  fs::create_symlink(b, a);
  fs::create_symlink(a, b);
  EXPECT_THROW(write_output(a.string(), std::string_view("x")), OutputError);
  EXPECT_TRUE(fs::is_symlink(a));
  EXPECT_THROW(write_output("", std::string_view("x")), OutputError);
}

TEST(OutputFile, DashIsStandardOutput) {
  TempDir d;
  const fs::path captured = d.path / "stdout.txt";
  std::fflush(stdout);
  const int saved = ::dup(STDOUT_FILENO);
  const int fd = ::open(captured.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  ASSERT_GE(fd, 0);
  ::dup2(fd, STDOUT_FILENO);
  ::close(fd);
  write_output("-", std::string_view("to stdout"));
  ::dup2(saved, STDOUT_FILENO);
  ::close(saved);
  EXPECT_EQ(slurp(captured), "to stdout");
  EXPECT_FALSE(fs::exists("-")) << "'-' must not become a file";
}

TEST(OutputFile, PlaceMovesAFinishedFileAcrossFoldersAndIntoStreams) {
  TempDir d;
  fs::create_directories(d.path / "work");
  fs::create_directories(d.path / "final");
  const fs::path done = d.path / "work" / "plot.png.tmp-1";
  std::ofstream(done) << "plot";
  const fs::path link = d.path / "work" / "plot.png";
  fs::create_symlink(d.path / "final" / "plot.png", link);
  place_output(done.string(), link.string());
  EXPECT_EQ(slurp(d.path / "final" / "plot.png"), "plot");
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_FALSE(fs::exists(done));
  const fs::path dev = make_null_device(d.path);
  if (dev.empty()) return;
  std::ofstream(done) << "again";
  place_output(done.string(), dev.string());
  EXPECT_TRUE(is_char_device(dev));
  EXPECT_FALSE(fs::exists(done));
}

TEST(OutputFile, TempNamesKeepTheExtensionOnlyWhenAsked) {
  // A left-over temp must not look like an output (*.vdb); writers that pick the format by
  // the name (ITK) ask for the extension.
  TempDir d;
  std::string seen;
  const auto fill = [&seen](const std::string& f) {
    seen = f;
    std::ofstream(f) << "x";
  };
  write_output((d.path / "a.vdb").string(), fill);
  EXPECT_EQ(seen.find(".tmp-"), (d.path / "a.vdb").string().size()) << seen;
  EXPECT_NE(fs::path(seen).extension(), ".vdb") << seen;
  write_output((d.path / "b.nii.gz").string(), fill, true);
  EXPECT_TRUE(seen.ends_with(".nii.gz")) << seen;
  EXPECT_NE(seen.find("b.nii.gz.tmp-"), std::string::npos) << seen;
  EXPECT_EQ(slurp(d.path / "b.nii.gz"), "x");
}

TEST(OutputFile, DevStdoutRedirectedToALogIsAppendedNotReplaced) {
  // `isotouch export ... --stl /dev/stdout >> build.log`: /dev/stdout resolves to the log
  // file, a regular file; replacing it would throw the log away.
  TempDir d;
  const fs::path log = d.path / "build.log";
  std::ofstream(log) << "earlier lines\n";
  struct stat before {};
  ASSERT_EQ(::stat(log.c_str(), &before), 0);
  std::fflush(stdout);
  const int saved = ::dup(STDOUT_FILENO);
  const int fd = ::open(log.c_str(), O_WRONLY | O_APPEND);
  ASSERT_GE(fd, 0);
  ::dup2(fd, STDOUT_FILENO);
  ::close(fd);
  const auto target = classify_output("/dev/stdout");
  write_output("/dev/stdout", std::string_view("the output\n"));
  write_output("/proc/self/fd/1", std::string_view("again\n"));
  ::dup2(saved, STDOUT_FILENO);
  ::close(saved);
  EXPECT_EQ(target.kind, OutputKind::kStream);
  EXPECT_EQ(slurp(log), "earlier lines\nthe output\nagain\n");
  struct stat after {};
  ASSERT_EQ(::stat(log.c_str(), &after), 0);
  EXPECT_EQ(after.st_ino, before.st_ino) << "the log file was replaced";
}
