// run_folder.h - an `isotouch run` output folder is complete or plainly marked.
#pragma once
#include <string>
#include <vector>

namespace isotouch::io {

/// The files an `isotouch run` may write into its output folder (also what an earlier run
/// left and a new run removes first). The lock file is not among them.
const std::vector<std::string>& run_output_files();

/// Name of the lock file in a run's output folder.
inline constexpr const char* kRunLockFile = ".isotouch-run.lock";

/// One run's hold on its output folder, from start to finish:
/// - the folder is created and locked (flock on `.isotouch-run.lock`, released when the
///   process ends however it ends): a second run into the same folder is refused;
/// - the files of an earlier run (run_output_files) are removed, so old and new never mix;
/// - summary.json says "status": "running" until the run writes its final summary
///   ("complete", written last), or mark_interrupted() writes "interrupted" with the stage
///   and the files that were finished, or mark_failed() "failed" with the error.
class RunFolder {
 public:
  /// @throws std::runtime_error "DIR: another isotouch run (pid N) is writing this folder ..."
  ///         or naming the folder and the OS error.
  RunFolder(std::string dir, const std::string& scene_file, const std::string& scene_name);
  ~RunFolder();
  RunFolder(const RunFolder&) = delete;
  RunFolder& operator=(const RunFolder&) = delete;

  const std::string& dir() const { return dir_; }
  /// Writes summary.json {"status": "interrupted", "stage", "signal", "files"} (files: the
  /// outputs present now). Never throws (returns false when it could not write).
  bool mark_interrupted(const std::string& stage, int signal) const noexcept;
  /// Writes summary.json {"status": "failed", "error", "files"}: the run stopped on an error.
  /// Never throws (returns false when it could not write).
  bool mark_failed(const std::string& error) const noexcept;

 private:
  bool mark(const std::string& status, const std::string& key, const std::string& value, const std::string& signal,
            const std::string& note) const noexcept;
  std::string dir_, scene_file_, scene_name_;
  int lock_fd_ = -1;
};

}  // namespace isotouch::io
