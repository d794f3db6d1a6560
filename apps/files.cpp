#include "files.h"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

extern char** environ;

namespace isotouch::app {

std::string temp_name(const std::string& path) { return path + ".tmp-" + std::to_string(::getpid()); }

void write_file_atomic(const std::string& path, const std::string& content) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);
  if (ec) throw std::runtime_error(path + ": cannot create folder: " + ec.message());
  const std::string tmp = temp_name(path);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw std::runtime_error(tmp + ": cannot open for writing: " + std::strerror(errno));
    out.write(content.data(), std::streamsize(content.size()));
    out.flush();
    if (!out) {
      std::remove(tmp.c_str());
      throw std::runtime_error(tmp + ": write failed: " + std::strerror(errno));
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp.c_str());
    throw std::runtime_error(path + ": cannot rename into place: " + why);
  }
}

int run_program(const std::string& program, const std::string& arg) {
  pid_t pid = 0;
  char* argv[] = {const_cast<char*>(program.c_str()), const_cast<char*>(arg.c_str()), nullptr};
  if (posix_spawnp(&pid, program.c_str(), nullptr, nullptr, argv, environ) != 0) return -1;
  int status = 0;
  if (waitpid(pid, &status, 0) < 0) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string gnuplot_quote(const std::string& s) {
  std::string o = "'";
  for (char c : s) o += c == '\'' ? std::string("''") : std::string(1, c);
  return o + "'";
}

std::string draw_with_gnuplot(const std::string& script_path, const std::string& script,
                              const std::vector<std::string>& pngs) {
  write_file_atomic(script_path, script);
  const int rc = run_program("gnuplot", script_path);
  for (const std::string& png : pngs) {
    if (rc == 0) std::filesystem::rename(temp_name(png), png);
    else std::remove(temp_name(png).c_str());
  }
  if (rc == 0) return "";
  return rc < 0 ? "gnuplot not found (Debian: gnuplot-nox); plots not drawn"
                : "gnuplot failed (exit " + std::to_string(rc) + "); plots not drawn";
}

}  // namespace isotouch::app
