// temp_dir.h - a fresh folder under the temp directory for one test, removed afterwards, and
// a file's bytes read back: what the output-writer tests share.
#pragma once
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace isotouch::test {

struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& tag = "isotouch-test") {
    std::string t = (std::filesystem::temp_directory_path() / (tag + "-XXXXXX")).string();
    path = ::mkdtemp(t.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
};

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace isotouch::test
