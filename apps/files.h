// files.h - output files are written whole or not at all (temp file + rename).
#pragma once
#include <string>

namespace isotouch::app {

/// Write `content` to `path` via `path.tmp-PID` and rename(2). Creates parent folders.
/// @throws std::runtime_error naming the path and the OS error.
void write_file_atomic(const std::string& path, const std::string& content);

/// Run a program (PATH lookup) with arguments, wait for it; returns its exit status,
/// or -1 if it could not be started.
int run_program(const std::string& program, const std::string& arg);

}  // namespace isotouch::app
