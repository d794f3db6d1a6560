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
/// (async-signal-safe); a second signal of any of them ends the process at once (the
/// default action). Idempotent.
void install_stop_handlers();

/// The signal that asked to stop, 0 when none did.
int stop_signal();

/// @throws Interrupted naming `stage` when a stop was asked for.
void throw_if_stop_requested(const std::string& stage);

/// Test hook: behave as if `signal` had arrived (0 clears).
void request_stop_for_test(int signal);

}  // namespace isotouch::session
