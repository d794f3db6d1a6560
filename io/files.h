// files.h - output files are written whole or not at all (temp file + rename).
#pragma once
#include <string>
#include <vector>

namespace isotouch::io {

/// Write `content` to `path` through the one output writer (io::write_output: a regular
/// file is replaced atomically, a device, FIFO or "-" written as a stream, a directory
/// refused). Creates parent folders. @throws io::OutputError (a std::runtime_error) naming
/// the path and the OS error.
void write_file_atomic(const std::string& path, const std::string& content);

/// Why `path` is not a regular file to read: "not a regular file (a FIFO)" (or a socket, a
/// device, a folder), or the OS error of stat ("No such file or directory"); "" for a regular
/// file (symlinks followed). Asked before open(): a FIFO's open() blocks until a writer comes.
std::string not_a_regular_file(const std::string& path);

/// Run a program (PATH lookup) with arguments, wait for it; returns its exit status,
/// or -1 if it could not be started.
int run_program(const std::string& program, const std::string& arg);

/// The name an output is written under before it is renamed into place: PATH.tmp-PID.
std::string temp_name(const std::string& path);

/// A gnuplot single-quoted string literal (quotes doubled).
std::string gnuplot_quote(const std::string& s);

/// Draw plots with gnuplot, whole or not at all, and keep a script that can be re-run.
/// `script` writes each PNG of `pngs` under its final name or under temp_name(png) (both
/// quoted with gnuplot_quote). Saved to `script_path`: the script naming the final PNGs,
/// with `set termoption noenhanced` after each `set terminal` (underscores in titles are
/// printed, not subscripts). Run now: a temp copy (temp_name(script_path) + "-run", removed
/// afterwards) writing temp_name(png), renamed into place on success, removed on failure.
/// Returns "" or why the plots were not drawn.
std::string draw_with_gnuplot(const std::string& script_path, const std::string& script,
                              const std::vector<std::string>& pngs);

}  // namespace isotouch::io
