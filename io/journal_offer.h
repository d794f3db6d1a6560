// journal_offer.h - what a program does with its edit journal at start: opens it, and
// offers what a session that did not end cleanly left there ("restore 214 edits from
// 14:02?"), as the user chose (--restore yes | no | ask). Shared by isotouch-sculpt and
// `isotouch serve`; each line it logs starts with "journal  ".
#pragma once
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "isotouch/io/journal.h"

namespace isotouch::io {

/// --restore: restore a journal left behind, drop it, or ask on the terminal (without one,
/// it is not restored and kept aside, PATH.unrestored).
enum class RestoreChoice { kYes, kNo, kAsk };
/// "yes", "no", "ask". @throws std::invalid_argument naming the value otherwise.
RestoreChoice restore_choice(const std::string& s);

struct OpenedJournal {
  std::unique_ptr<Journal> journal;        ///< null: journal off (the log says why)
  std::vector<session::EditEvent> restore; ///< the edits to apply before the session starts
  /// With `restore`: the isovalue the journaled session ran at (absent: the volume's own)
  /// and where its undo history started afresh (JournalLeft).
  std::optional<core::Isosurface> isovalue;
  std::vector<std::size_t> history_restarts;
};

/// Opens PROGRAM's journal of the volume of CRC `volume_crc32` in journal_dir(), and decides
/// about what it holds. A journal that cannot be applied (another volume, not a journal) is
/// named on `log` and copied to PATH.refused; one not restored is copied to PATH.unrestored
/// (the file is then started afresh by Journal::start). `answers`: where a kAsk reads its
/// y/n when `ask_terminal` (the program's stdin is a terminal). Never throws: a journal
/// that cannot be opened (a running session holds it, no HOME) is off, said on `log`.
OpenedJournal open_journal(const std::string& program, std::uint32_t volume_crc32, RestoreChoice choice,
                           std::ostream& log, std::istream& answers, bool ask_terminal);

/// Applies a journal's `edits` to `es` in order (undo and redo included: the volume and its
/// history become those at the crash), publishing into `out` (may be null); the undo
/// history is dropped after each count in `history_restarts` (ascending: where the journaled
/// session was rebuilt). A stroke the crash left open is closed: that end_stroke is appended
/// to `edits`, so the new journal holds it too. @throws what EditSession::apply throws (the
/// journal file is untouched).
void apply_restored(session::EditSession& es, std::vector<session::EditEvent>& edits,
                    servo::TripleBuffer<core::SampleField>* out, const std::vector<std::size_t>& history_restarts = {});

}  // namespace isotouch::io
