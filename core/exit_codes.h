// exit_codes.h - the exit status of every isotouch command (isotouch and its subcommands,
// isotouch-sculpt, isotouch-devemu), in one place. docs/exit-codes.md is the table a user
// reads; tests/cli_exit_codes.cmake checks a few of them from the command line.
#pragma once

namespace isotouch::exit_code {

inline constexpr int kOk = 0;
/// Bad input: a file, scene field or value that cannot be used (the message names the file,
/// field and value), or any other error that stopped the command.
inline constexpr int kError = 1;
/// The command line itself: an unknown option, a missing or malformed argument, a value out
/// of its range (the message names the option).
inline constexpr int kUsage = 2;
/// A check failed: `check` / `check --all` disagreement, `export`'s mesh written but not
/// closed, the Vulkan validation layer reported a message (isotouch-sculpt --validation).
inline constexpr int kCheckFailed = 3;
/// `run`: servo ticks were faults (zero force sent; the run is not trustworthy).
inline constexpr int kServoFaults = 4;
/// The haptic device was disconnected, faulty or sent refused reports (`run --live`,
/// isotouch-sculpt).
inline constexpr int kDeviceLost = 5;
/// isotouch-sculpt: a scripted save or export (Ctrl+S / Ctrl+E in --script) failed;
/// `isotouch serve`: a `save` command could not write (answered with a STATUS, the session went on).
inline constexpr int kSaveFailed = 6;
/// The servo thread was abandoned inside a renderer that did not return within the stop
/// timeout (`run --live`, `serve`, isotouch-sculpt): the force was turned off, what had to
/// be written was written (the recording completed, a run folder marked failed), and the
/// process ended at once without freeing what that thread may still touch.
inline constexpr int kServoStuck = 7;
/// `replay`: the replay differs from the recording (the first differing tick is printed).
inline constexpr int kReplayDiffers = 1;
/// `replay`: the recording, its scene or its volume cannot be used.
inline constexpr int kReplayBadInput = 2;
/// `replay`: the pipeline could not run (no Vulkan device, ...).
inline constexpr int kReplayCannotRun = 3;
/// Stopped by SIGINT or SIGTERM: 128 + the signal (130, 143), as a shell reports it.
inline constexpr int kSignalBase = 128;
inline constexpr int signalled(int signal) { return kSignalBase + signal; }

}  // namespace isotouch::exit_code
