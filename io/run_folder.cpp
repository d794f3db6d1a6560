#include "isotouch/io/run_folder.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "isotouch/io/files.h"

namespace isotouch::io {
namespace fs = std::filesystem;

const std::vector<std::string>& run_output_files() {
  static const std::vector<std::string> files = {
      "summary.json", "report.md",  "trace.csv",       "plots.gp",       "force_depth.png", "tick_time.png",
      "surface.png",  "edits.csv",  "edits.gp",        "edits.png",      "before.png",      "after.png",
      "section_before.png", "section_after.png", "drill.png", "drilled.vdb", "drilled.nrrd", "drilled.stl"};
  return files;
}

namespace {

/// " (pid N)" when the lock file names a live process, "" otherwise.
std::string holder_pid(int fd) {
  char buf[32] = {};
  const ssize_t n = ::pread(fd, buf, sizeof buf - 1, 0);
  const long pid = n > 0 ? std::strtol(buf, nullptr, 10) : 0;
  if (pid <= 0 || (::kill(pid_t(pid), 0) != 0 && errno != EPERM)) return "";
  return " (pid " + std::to_string(pid) + ")";
}

nlohmann::ordered_json status_json(const std::string& status, const std::string& file, const std::string& name) {
  nlohmann::ordered_json j;
  j["status"] = status;
  j["scene"] = {{"file", file}, {"name", name}};
  return j;
}

}  // namespace

RunFolder::RunFolder(std::string dir, const std::string& scene_file, const std::string& scene_name)
    : dir_(std::move(dir)), scene_file_(scene_file), scene_name_(scene_name) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec || !fs::is_directory(dir_))
    throw std::runtime_error(dir_ + ": cannot use as the output folder: " + (ec ? ec.message() : "not a folder"));
  const std::string lock = (fs::path(dir_) / kRunLockFile).string();
  lock_fd_ = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock_fd_ < 0) throw std::runtime_error(lock + ": cannot create the lock file: " + std::strerror(errno));
  if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    const std::string pid = holder_pid(lock_fd_);
    ::close(lock_fd_);
    lock_fd_ = -1;
    throw std::runtime_error(dir_ + ": another isotouch run" + pid + " is writing this folder (it holds " + lock +
                             "); wait for it to finish or choose another --out");
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(lock_fd_, 0) == 0) (void)!::pwrite(lock_fd_, pid.data(), pid.size(), 0);
  for (const std::string& f : run_output_files()) {
    fs::remove(fs::path(dir_) / f, ec);
    if (ec) throw std::runtime_error((fs::path(dir_) / f).string() + ": cannot remove the earlier run's file: " + ec.message());
  }
  write_file_atomic((fs::path(dir_) / "summary.json").string(),
                    status_json("running", scene_file_, scene_name_).dump(2) + "\n");
}

RunFolder::~RunFolder() {
  if (lock_fd_ >= 0) ::close(lock_fd_);  // releases the flock
}

bool RunFolder::mark(const std::string& status, const std::string& key, const std::string& value,
                     const std::string& signal, const std::string& note) const noexcept {
  try {
    nlohmann::ordered_json j = status_json(status, scene_file_, scene_name_);
    if (!signal.empty()) j["signal"] = signal;
    j[key] = value;
    nlohmann::ordered_json files = nlohmann::ordered_json::array();
    for (const std::string& f : run_output_files()) {
      std::error_code ec;
      if (f != "summary.json" && fs::exists(fs::path(dir_) / f, ec)) files.push_back(f);
    }
    j["files"] = files;
    j["note"] = note;
    write_file_atomic((fs::path(dir_) / "summary.json").string(), j.dump(2) + "\n");
    return true;
  } catch (...) {
    return false;
  }
}

bool RunFolder::mark_interrupted(const std::string& stage, int signal) const noexcept {
  return mark("interrupted", "stage", stage, signal == SIGTERM ? "SIGTERM" : "SIGINT",
              "the run was stopped before it finished: the files listed are whole but the figures of a complete run "
              "(report.md, the rest of summary.json) were not written");
}

bool RunFolder::mark_failed(const std::string& error) const noexcept {
  return mark("failed", "error", error, "",
              "the run stopped on this error: the files listed are whole, the figures of a complete run were not written");
}

}  // namespace isotouch::io
