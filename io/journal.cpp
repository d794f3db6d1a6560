// journal.cpp - the edit journal (see journal.h): a locked file, a writer thread that
// writes each append as it comes and fdatasyncs every flush interval, and the reader of
// what a killed session left.
#include "isotouch/io/journal.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <thread>

namespace isotouch::io {
namespace {

std::string os_error(const std::string& path, const char* what) { return path + ": " + what + ": " + std::strerror(errno); }

std::string hex8(std::uint32_t v) {
  char s[9];
  std::snprintf(s, sizeof s, "%08x", v);
  return s;
}

/// Writes all of `text` at the file's end (into the page cache: a killed process's writes
/// stay). @throws JournalError naming the file.
void write_all(int fd, const std::string& text, const std::string& path) {
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw JournalError(os_error(path, "journal write failed"));
    done += std::size_t(n);
  }
}

/// To the disk (a power cut). @throws JournalError naming the file.
void sync(int fd, const std::string& path) {
  if (::fdatasync(fd) != 0) throw JournalError(os_error(path, "journal fdatasync failed"));
}

/// The rename of a file in `path`'s folder made durable (best effort: a folder that cannot
/// be opened or synced leaves the rename to the file system's own schedule).
void sync_folder(const std::string& path) {
  const auto dir = std::filesystem::path(path).parent_path();
  const int d = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (d < 0) return;
  (void)::fsync(d);
  ::close(d);
}

std::string read_all(int fd, const std::string& path) {
  std::string out;
  char buf[1 << 16];
  for (off_t at = 0;;) {
    const ssize_t n = ::pread(fd, buf, sizeof buf, at);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw JournalError(os_error(path, "journal read failed"));
    if (n == 0) return out;
    out.append(buf, std::size_t(n));
    at += n;
  }
}

}  // namespace

std::string journal_dir() {
  const char* state = std::getenv("XDG_STATE_HOME");
  if (state && *state) return (std::filesystem::path(state) / "isotouch").string();
  const char* home = std::getenv("HOME");
  if (home && *home) return (std::filesystem::path(home) / ".local" / "state" / "isotouch").string();
  throw JournalError("the edit journal needs XDG_STATE_HOME or HOME set (neither is)");
}

std::string journal_path(const std::string& dir, const std::string& program, std::uint32_t volume_crc32) {
  return (std::filesystem::path(dir) / (program + "-" + hex8(volume_crc32) + ".journal")).string();
}

std::string restore_question(const JournalLeft& left) {
  char hhmm[16] = "?";
  std::tm tm{};
  if (localtime_r(&left.written, &tm)) std::strftime(hhmm, sizeof hhmm, "%H:%M", &tm);
  std::string q = "restore " + std::to_string(left.edits.size()) + " edits from " + hhmm + "?";
  if (left.dropped_bytes > 0)
    q += " (the last record was cut by the crash: " + std::to_string(left.dropped_bytes) + " bytes dropped)";
  return q;
}

struct Journal::Impl {
  int fd = -1;
  double flush_interval_s = 0.25;
  std::mutex mu;
  std::condition_variable cv;
  std::string pending;   // lines appended, not yet written (guarded by mu)
  long edits = 0;        // guarded by mu
  bool stop = false;     // guarded by mu
  std::string error;     // the first failed write or sync (guarded by mu)
  std::mutex io_mu;      // one writer of the file at a time: the thread, flush(), close()
  bool unsynced = false; // written since the last fdatasync (guarded by io_mu)
  std::thread writer;

  /// Writes what is pending, and fdatasyncs what was written when `sync_now`. A failure is
  /// kept in `error` (nothing more is written then).
  void drain(const std::string& path, bool sync_now) {
    std::lock_guard<std::mutex> io(io_mu);
    std::string text;
    {
      std::lock_guard<std::mutex> lock(mu);
      if (!error.empty()) return;
      text.swap(pending);
    }
    try {
      if (!text.empty()) write_all(fd, text, path);
      unsynced = unsynced || !text.empty();
      if (sync_now && unsynced) sync(fd, path);
      unsynced = unsynced && !sync_now;
    } catch (const JournalError& e) {
      std::lock_guard<std::mutex> lock(mu);
      error = e.what();
    }
  }
  /// Writes each append as soon as it comes (a fdatasync in progress holds it back, not the
  /// appender); fdatasyncs every flush interval.
  void loop(const std::string& path) {
    const auto interval = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(flush_interval_s));
    auto next_sync = std::chrono::steady_clock::now() + interval;
    std::unique_lock<std::mutex> lock(mu);
    while (!stop) {
      cv.wait_until(lock, next_sync, [&] { return stop || !pending.empty(); });
      const bool sync_now = std::chrono::steady_clock::now() >= next_sync;
      lock.unlock();
      drain(path, sync_now);
      if (sync_now) next_sync = std::chrono::steady_clock::now() + interval;
      lock.lock();
    }
  }
  void stop_writer() {
    {
      std::lock_guard<std::mutex> lock(mu);
      stop = true;
    }
    cv.notify_all();
    if (writer.joinable()) writer.join();
  }
};

Journal::Journal(std::string path, double flush_interval_s) : path_(std::move(path)), impl_(std::make_unique<Impl>()) {
  if (!(flush_interval_s > 0 && flush_interval_s <= 1.0))
    throw std::invalid_argument("journal flush interval must be in (0, 1] s, got " + std::to_string(flush_interval_s));
  impl_->flush_interval_s = flush_interval_s;
  std::error_code ec;
  const auto dir = std::filesystem::path(path_).parent_path();
  if (!dir.empty()) std::filesystem::create_directories(dir, ec);
  if (ec) throw JournalError(dir.string() + ": cannot create the journal folder: " + ec.message());
  impl_->fd = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (impl_->fd < 0) throw JournalError(os_error(path_, "cannot open the edit journal"));
  if (::flock(impl_->fd, LOCK_EX | LOCK_NB) != 0) {
    const bool held = errno == EWOULDBLOCK;
    const std::string why = held ? path_ + ": the edit journal is held by another running session on this volume"
                                 : os_error(path_, "cannot lock the edit journal");
    ::close(impl_->fd);
    throw JournalError(why);
  }
}

Journal::~Journal() {
  impl_->stop_writer();
  impl_->drain(path_, true);
  if (impl_->fd >= 0) ::close(impl_->fd);
}

std::optional<JournalLeft> Journal::left(std::uint32_t volume_crc32) const {
  const std::string text = read_all(impl_->fd, path_);
  if (text.empty()) return std::nullopt;
  JournalLeft out;
  const std::size_t whole = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
  out.dropped_bytes = text.size() - whole;
  Recording r;
  try {
    r = parse_recording(text, path_, true);  // drops the cut last line
  } catch (const RecordingError& e) {
    throw JournalError(std::string(e.what()) + " (not an edit journal; nothing restored)");
  }
  if (r.format_version != 3 || !r.volume_crc32 || !r.ticks.empty())
    throw JournalError(path_ + ": not an edit journal (a recording with ticks or of format " +
                       std::to_string(r.format_version) + "); nothing restored");
  if (*r.volume_crc32 != volume_crc32)
    throw JournalError(path_ + ": field 'volume_crc32': the journal is of another volume (" + hex8(*r.volume_crc32) +
                       ", this one is " + hex8(volume_crc32) + "); nothing restored");
  struct stat st {};
  if (::fstat(impl_->fd, &st) == 0) out.written = st.st_mtime;
  if (!r.history_restarts.empty() && r.history_restarts.back() > r.edits.size())
    throw JournalError(path_ + ": field 'history_restarts': " + std::to_string(r.history_restarts.back()) +
                       " is past the journal's " + std::to_string(r.edits.size()) + " edits; nothing restored");
  out.edits = std::move(r.edits);
  out.input = r.scene_path;
  out.isovalue = r.isovalue;
  out.history_restarts = std::move(r.history_restarts);
  return out;
}

void Journal::start(Recording header, const std::vector<session::EditEvent>& restored) {
  header.format_version = 3;
  header.ticks.clear();
  header.edits.clear();
  std::string text = recording_header_line(header, path_);
  for (session::EditEvent e : restored) {
    e.tick = 0;  // applied before this session's first tick
    text += recording_edit_line(e, path_);
  }
  // Written whole beside the journal, locked, synced, then renamed over it: until the rename
  // the journal a crash left stays as it was (its edits may be in memory only now).
  const std::string next = path_ + ".new";
  const int fd = ::open(next.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) throw JournalError(os_error(next, "cannot create the edit journal"));
  // The writer first (std::system_error where no thread can be made): nothing that can fail
  // comes after the rename. It writes nothing before an append, and appends come after start().
  try {
    {
      std::lock_guard<std::mutex> lock(impl_->mu);
      impl_->stop = false;  // a start after a failed one
    }
    impl_->writer = std::thread([this] { impl_->loop(path_); });
  } catch (...) {
    ::close(fd);
    ::unlink(next.c_str());
    throw;
  }
  try {
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) throw JournalError(os_error(next, "cannot lock the edit journal"));
    write_all(fd, text, next);
    sync(fd, next);
    if (::rename(next.c_str(), path_.c_str()) != 0) throw JournalError(os_error(path_, "cannot replace the edit journal"));
  } catch (...) {
    ::close(fd);
    ::unlink(next.c_str());
    impl_->stop_writer();
    throw;
  }
  sync_folder(path_);
  {
    std::lock_guard<std::mutex> io(impl_->io_mu);  // the writer's file from here
    ::close(impl_->fd);  // the old file's lock goes with it; the new one is locked already
    impl_->fd = fd;
  }
  std::lock_guard<std::mutex> lock(impl_->mu);
  impl_->edits = long(restored.size());
}

void Journal::restart(Recording header, const std::vector<session::EditEvent>& kept) {
  impl_->stop_writer();
  impl_->drain(path_, true);
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    if (!impl_->error.empty()) throw JournalError(impl_->error + " (the journal is kept)");
  }
  try {
    start(std::move(header), kept);
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(impl_->mu);
    impl_->error = e.what();  // appends are dropped from now on, not queued for no writer
    impl_->stop = true;
    throw;
  }
}

void Journal::append(const session::EditEvent& e) noexcept {
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    if (!impl_->error.empty()) return;
    try {
      impl_->pending += recording_edit_line(e, path_);
      ++impl_->edits;
    } catch (const std::exception& x) {
      impl_->error = x.what();
    }
  }
  impl_->cv.notify_one();
}

void Journal::flush() {
  impl_->drain(path_, true);
  std::lock_guard<std::mutex> lock(impl_->mu);
  if (!impl_->error.empty()) throw JournalError(impl_->error);
}

void Journal::close() {
  impl_->stop_writer();
  impl_->drain(path_, true);
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    if (!impl_->error.empty()) throw JournalError(impl_->error + " (the journal is kept)");
  }
  if (::unlink(path_.c_str()) != 0) throw JournalError(os_error(path_, "cannot delete the edit journal"));
}

long Journal::edits() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->edits;
}

}  // namespace isotouch::io
