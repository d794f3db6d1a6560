// output_file.h - the one writer of every output file (summary.json, CSVs, PNGs, .vdb,
// meshes, recordings, plots): whole or not at all, and never over something that is not a
// regular file.
#pragma once
#include <functional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace isotouch::io {

/// An output that could not be written; what() names the path and the reason.
struct OutputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// How an output path is written.
enum class OutputKind {
  kReplace,  ///< a regular file or nothing: a temp file beside it, fsync, rename(2), fsync the folder
  kStream,   ///< a character device, a FIFO or "-" (standard output): written in place, in order
};

/// Where an output goes, after following symlinks.
struct OutputTarget {
  std::string requested;  ///< the path as given
  std::string resolved;   ///< the final target after following symlinks ("-" for a standard stream)
  OutputKind kind = OutputKind::kReplace;
  int fd = -1;            ///< a standard stream (1 or 2) the target is: written on that descriptor
};

/// Classifies `path`: "-" is standard output (stream), and so is any path that is the file
/// standard output or standard error already writes (/dev/stdout redirected to a log
/// file: written on the descriptor, never replaced); a symlink is followed (chains too,
/// relative links against the link's folder, at most 40 hops) and its target classified by
/// the same rules; a regular file or a path that does not exist yet is replaced atomically;
/// a character device or a FIFO is written as a stream. A directory, a block device, a
/// socket, a symlink loop or an empty path is refused.
/// @throws OutputError "PATH: cannot write an output here: it is a directory" and the like.
OutputTarget classify_output(const std::string& path);

/// Writes `path` whole or not at all. `fill(file)` writes the content into `file`, a fresh
/// empty file made for it (beside the final target when that target is replaced, in the
/// temp folder when it is a stream; with `keep_extension` its name ends in the target's
/// extension, ".nii.gz" included, for writers that choose the format by the name, otherwise
/// in ".tmp-PID-XXXXXX" so a left-over temp never matches the target's kind, e.g. *.vdb); on success the file is renamed over the target or
/// copied into the stream. When `fill` throws, or any step fails, the temp file is removed
/// and the old target is untouched (a stream may have received a part). The folder of a
/// replaced target must exist (a missing one is an error naming it, not created).
/// @throws OutputError naming the path and the OS error; rethrows what `fill` throws.
void write_output(const std::string& path, const std::function<void(const std::string& file)>& fill,
                  bool keep_extension = false);

/// write_output of a byte string.
void write_output(const std::string& path, std::string_view content);

/// Moves a finished file `done` (written by another program, e.g. gnuplot) to `path` by the
/// rules of classify_output: renamed (or copied beside the target and renamed, across
/// folders) over a regular file, copied into a stream. `done` is gone afterwards, also on
/// failure. @throws OutputError naming the path.
void place_output(const std::string& done, const std::string& path);

/// Writes all `size` bytes to the open descriptor `fd` (retried on EINTR and short writes):
/// for a file that must grow in place, such as a live session's streamed recording.
/// @throws OutputError naming `path` and the OS error.
void write_all(int fd, const char* data, std::size_t size, const std::string& path);

}  // namespace isotouch::io
