// stop_signal.h - SIGINT / SIGTERM / SIGHUP / SIGQUIT ask a long command to stop at its next safe point.
#pragma once
#include <stdexcept>
#include <string>

namespace isotouch::session {

/// Thrown at a safe point after a stop signal: `stage` says where the work stopped.
struct Interrupted : std::runtime_error {
  Interrupted(int signal, std::string stage);
  int signal;         ///< SIGINT, SIGTERM, SIGHUP or SIGQUIT
  std::string stage;  ///< e.g. "servo simulation, tick 1250 of 5001"
};

/// Installs handlers for SIGINT, SIGTERM, SIGHUP and SIGQUIT that only raise a flag
/// (async-signal-safe); a second signal of any of them ends the process at once (the default
/// action: exit status 128 + the signal), after writing the last words if any are set.
/// Idempotent.
void install_stop_handlers();

/// While set, a second SIGINT / SIGTERM first replaces the file `path` with `on_sigint` /
/// `on_sigterm` (written to a temporary file beside it and renamed over it: whole or not
/// at all; open, write and rename are async-signal-safe), so that a status file (a run's
/// summary.json) never stays at "running" after the process ended. Replaces what was set.
void set_last_words(const std::string& path, const std::string& on_sigint, const std::string& on_sigterm);

/// Ends the process now as a second signal would (the last words written, then the
/// signal's default action: exit status 128 + `signal`), for a command asked to stop while
/// in work it cannot cut short (one long GPU submission). Call after its own status is
/// written and its streams flushed. Never returns.
[[noreturn]] void end_process_now(int signal);

/// No last words any more (the command wrote its own final status). Idempotent.
void clear_last_words();

/// The signal that asked to stop, 0 when none did.
int stop_signal();

/// @throws Interrupted naming `stage` when a stop was asked for.
void throw_if_stop_requested(const std::string& stage);

/// Test hook: behave as if `signal` had arrived (0 clears).
void request_stop_for_test(int signal);

}  // namespace isotouch::session
