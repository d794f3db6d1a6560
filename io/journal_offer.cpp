// journal_offer.cpp - opening the edit journal at start and offering its edits (see journal_offer.h).
#include "isotouch/io/journal_offer.h"

#include "isotouch/session/brush.h"

#include <filesystem>
#include <istream>
#include <ostream>
#include <stdexcept>

namespace isotouch::io {
namespace {

/// Copies the journal aside before it is started afresh: to PATH + suffix, or PATH + suffix
/// + ".N" (N = 2, 3, ...) where an earlier one is there (never overwritten). `said` gets the
/// copy's name or why there is none; false: no copy (the journal must not be started).
bool keep_aside(const std::string& path, const char* suffix, std::string& said) {
  std::string to = path + suffix;
  for (int n = 2; std::filesystem::exists(to) && n < 1000; ++n) to = path + suffix + "." + std::to_string(n);
  std::error_code ec;
  if (!std::filesystem::copy_file(path, to, std::filesystem::copy_options::none, ec) || ec) {
    said = "could not be kept (" + to + ": " + (ec ? ec.message() : std::string("exists")) +
           "); the journal is left as it is and this session's edits are not journaled";
    return false;
  }
  said = "kept in " + to;
  return true;
}

bool answered_yes(std::istream& answers) {
  std::string line;
  if (!std::getline(answers, line)) return false;
  return !line.empty() && (line[0] == 'y' || line[0] == 'Y');
}

}  // namespace

RestoreChoice restore_choice(const std::string& s) {
  if (s == "yes") return RestoreChoice::kYes;
  if (s == "no") return RestoreChoice::kNo;
  if (s == "ask") return RestoreChoice::kAsk;
  throw std::invalid_argument("--restore: \"" + s + "\" is not yes, no or ask");
}

OpenedJournal open_journal(const std::string& program, std::uint32_t volume_crc32, RestoreChoice choice,
                           std::ostream& log, std::istream& answers, bool ask_terminal) {
  OpenedJournal out;
  std::string path;
  try {
    path = journal_path(journal_dir(), program, volume_crc32);
    out.journal = std::make_unique<Journal>(path);
  } catch (const std::exception& e) {
    log << "journal  off: " << e.what() << " (the edits of this session are not kept through a crash)\n";
    return out;
  }
  std::optional<JournalLeft> left;
  try {
    left = out.journal->left(volume_crc32);
  } catch (const JournalError& e) {
    std::string said;
    if (!keep_aside(path, ".refused", said)) out.journal.reset();
    log << "journal  " << e.what() << "; " << said << "\n";
    return out;
  }
  if (!left || left->edits.empty()) return out;  // new, closed, or killed before any edit
  const std::string question = restore_question(*left);
  bool yes = choice == RestoreChoice::kYes;
  if (choice == RestoreChoice::kAsk && ask_terminal) {
    log << "journal  " << question << " [y/N] " << std::flush;
    yes = answered_yes(answers);
  } else {
    log << "journal  " << question << "\n";
  }
  if (yes) {
    log << "journal  restoring " << left->edits.size() << " edits from " << path << "\n";
    out.restore = std::move(left->edits);
    out.isovalue = left->isovalue;
    out.history_restarts = std::move(left->history_restarts);
    return out;
  }
  const char* why = choice == RestoreChoice::kNo ? "--restore no"
                    : ask_terminal               ? "answered no"
                                                 : "no terminal to ask; --restore yes restores";
  std::string said;
  if (!keep_aside(path, ".unrestored", said)) out.journal.reset();
  log << "journal  not restored (" << why << "): " << said << "\n";
  return out;
}

void apply_restored(session::EditSession& es, std::vector<session::EditEvent>& edits,
                    servo::TripleBuffer<core::SampleField>* out, const std::vector<std::size_t>& history_restarts) {
  std::size_t next = 0;
  for (std::size_t i = 0; i <= edits.size(); ++i) {
    for (; next < history_restarts.size() && history_restarts[next] == i; ++next) es.sculptor().drop_history();
    if (i < edits.size()) (void)es.apply(edits[i], out);
  }
  if (!es.sculptor().history().stroke_open()) return;
  session::EditEvent end;
  end.kind = session::EditEvent::Kind::kEndStroke;
  (void)es.apply(end, out);
  edits.push_back(end);
}

}  // namespace isotouch::io
