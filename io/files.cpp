#include "isotouch/io/files.h"

#include "isotouch/io/output_file.h"

#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

extern char** environ;

namespace isotouch::io {

std::string temp_name(const std::string& path) { return path + ".tmp-" + std::to_string(::getpid()); }

void write_file_atomic(const std::string& path, const std::string& content) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty() && path != "-") std::filesystem::create_directories(parent, ec);
  if (ec) throw io::OutputError(path + ": cannot create the folder '" + parent.string() + "': " + ec.message());
  io::write_output(path, content);
}

std::string not_a_regular_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::strerror(errno);
  if (S_ISREG(st.st_mode)) return "";
  const char* kind = S_ISFIFO(st.st_mode)  ? "a FIFO"
                     : S_ISSOCK(st.st_mode) ? "a socket"
                     : S_ISCHR(st.st_mode)  ? "a character device"
                     : S_ISBLK(st.st_mode)  ? "a block device"
                     : S_ISDIR(st.st_mode)  ? "a folder"
                                            : "of an unknown kind";
  return std::string("not a regular file (") + kind + ")";
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

namespace {
void replace_all(std::string& s, const std::string& from, const std::string& to) {
  if (from.empty()) return;
  for (std::size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size()))
    s.replace(at, from.size(), to);
}

/// After every `set terminal` / `set term` line, `set termoption noenhanced`: titles and
/// keys are printed as written (an underscore is not a subscript).
std::string with_noenhanced(const std::string& script) {
  std::string out;
  std::size_t at = 0;
  while (at < script.size()) {
    std::size_t end = script.find('\n', at);
    const std::string line = script.substr(at, end == std::string::npos ? std::string::npos : end - at);
    out += line;
    out += '\n';
    const std::size_t first = line.find_first_not_of(" \t");
    if (first != std::string::npos && line.compare(first, 8, "set term") == 0 &&
        line.compare(first, 14, "set termoption") != 0)
      out += "set termoption noenhanced\n";
    if (end == std::string::npos) break;
    at = end + 1;
  }
  return out;
}
}  // namespace

std::string draw_with_gnuplot(const std::string& script_path, const std::string& script,
                              const std::vector<std::string>& pngs) {
  // Two texts of the same script: the saved one names the final PNGs (re-runnable), the
  // one gnuplot runs now names the temp files, renamed into place only on success.
  std::string saved = with_noenhanced(script), to_run = saved;
  for (const std::string& png : pngs) {
    replace_all(saved, gnuplot_quote(temp_name(png)), gnuplot_quote(png));
    replace_all(to_run, gnuplot_quote(png), gnuplot_quote(temp_name(png)));
  }
  write_file_atomic(script_path, saved);
  const std::string run_path = temp_name(script_path) + "-run";
  write_file_atomic(run_path, to_run);
  const int rc = run_program("gnuplot", run_path);
  std::remove(run_path.c_str());
  std::string placed;
  for (const std::string& png : pngs) {
    if (rc != 0) {
      std::remove(temp_name(png).c_str());
      continue;
    }
    try {
      io::place_output(temp_name(png), png);
    } catch (const std::exception& e) {
      if (placed.empty()) placed = e.what();
    }
  }
  if (rc == 0 && placed.empty()) return "";
  if (rc == 0) return "gnuplot's plots not placed: " + placed;
  return rc < 0 ? "gnuplot not found (Debian: gnuplot-nox); plots not drawn"
                : "gnuplot failed (exit " + std::to_string(rc) + "); plots not drawn";
}

}  // namespace isotouch::io
