// journal.h - the edit journal: every edit a sculpting session applies, appended to a file
// beside the session so that a crash or `kill -9` loses none of them.
//
// The file is a recording without ticks (io/record.h, format 3): the header (the volume's
// CRC-32, the program and input it was opened by; for `isotouch serve`, the session's
// isovalue and where an `isovalue V` restarted its undo history) and one edit line per
// applied edit, in the order applied. Appending costs a mutex and a string (the edit thread's: never the
// servo tick, never a wait for the disk); a writer thread writes each append as it comes
// (a killed process loses only what it had not yet written: microseconds, or a fdatasync in
// progress) and fdatasyncs every flush interval (at most 1 s: a power cut). The file
// is locked (flock) while a session holds it, so a journal whose lock is free was left by a
// process that did not end cleanly: that is the journal offered for restore.
//
// Where: journal_dir() (XDG state: $XDG_STATE_HOME/isotouch, else ~/.local/state/isotouch),
// one file per program and volume: PROGRAM-CRC.journal (CRC: volume_crc32 of the volume as
// read from its file, 8 hex digits).
#pragma once
#include <cstdint>
#include <ctime>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/io/record.h"
#include "isotouch/session/edit_session.h"

namespace isotouch::io {

/// A journal that cannot be used: what() names the file and the cause (another process holds
/// it, a journal of another volume, a write that failed).
struct JournalError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// $XDG_STATE_HOME/isotouch, else $HOME/.local/state/isotouch (not created here).
/// @throws JournalError when neither variable is set.
std::string journal_dir();
/// DIR/PROGRAM-CRC.journal, CRC as 8 lower-case hex digits.
std::string journal_path(const std::string& dir, const std::string& program, std::uint32_t volume_crc32);

/// What a session that did not end cleanly left in its journal.
struct JournalLeft {
  std::vector<session::EditEvent> edits;  ///< every whole record, in the order applied
  std::size_t dropped_bytes = 0;          ///< a record cut by the kill (no newline): dropped
  std::time_t written = 0;                ///< the file's last write (its mtime) [s since the epoch]
  std::string input;                      ///< the input the session opened (the header's scene_path)
  /// The isovalue the session ran at, where a client's `isovalue V` rebuilt it (Recording::isovalue).
  std::optional<core::Isosurface> isovalue;
  /// After how many of `edits` its undo history started afresh (Recording::history_restarts).
  std::vector<std::size_t> history_restarts;
};

/// "restore 214 edits from 14:02?" (HH:MM: `left.written`, local time), with the dropped
/// bytes when a record was cut.
std::string restore_question(const JournalLeft& left);

class Journal {
 public:
  /// Opens (creates) `path` and its folder, and takes its lock.
  /// @throws JournalError naming the file: it cannot be created, or another running process
  ///         holds it (a second session on the same volume).
  explicit Journal(std::string path, double flush_interval_s = 0.25);
  /// Stops the writer after writing and fdatasyncing what is pending, and keeps the file (an
  /// error exit: the next start offers it); close() is the clean end.
  ~Journal();
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  /// What the file holds from a session that did not end cleanly; nullopt when it is empty
  /// (new, or closed). Call before start().
  /// @throws JournalError naming the file when its header's volume_crc32 is not
  ///         `volume_crc32` (a journal of another volume: nothing is applied), or it is not a
  ///         journal (names the line and field; a history restart past its edits too).
  std::optional<JournalLeft> left(std::uint32_t volume_crc32) const;
  /// Starts this session's journal: the file is emptied, then holds `header` (a format 3
  /// recording header: volume_crc32 and rate_hz required, no ticks) and `restored` (the
  /// edits restored from the last one, their tick set to 0), fdatasync'ed; then the writer runs.
  /// @throws JournalError naming the file (write failed), RecordingError (bad header).
  void start(Recording header, const std::vector<session::EditEvent>& restored);
  /// start() again on this running journal, for the session that replaces its own on the
  /// same volume (serve's `isovalue V`): the writer stopped, what is queued written, then
  /// `header` and `kept` replace the file as in start(), the lock held throughout (no other
  /// session can take the file between the two). When it throws, the file is as it was and
  /// still locked, and nothing more is written to it.
  /// @throws JournalError naming the file (an earlier write failed, or this one did),
  ///         RecordingError (a bad header), std::system_error (no writer thread).
  void restart(Recording header, const std::vector<session::EditEvent>& kept);
  /// Queues one applied edit's line for the writer (written at once, fdatasync'ed within the
  /// flush interval). Any thread; no wait for the disk. A failed write is kept, reported by
  /// flush() and close(); nothing later is written then.
  void append(const session::EditEvent& e) noexcept;
  /// Writes what is queued and fdatasyncs it now. @throws JournalError on a failed write or sync.
  void flush();
  /// The clean end: writes and fdatasyncs what is queued, stops the writer, deletes the file.
  /// @throws JournalError when a write failed at some point (the file is kept).
  void close();
  const std::string& path() const { return path_; }
  /// Edits in the journal so far (restored + appended).
  long edits() const;

 private:
  struct Impl;
  std::string path_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotouch::io
