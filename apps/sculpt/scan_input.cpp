#include "isotouch/apps/sculpt/scan_input.h"

#include <filesystem>

#include "isotouch/io/scan.h"

namespace isotouch::sculpt {

ScanInput open_scan(const std::string& path) {
  io::Scan s = io::load_scan(path);
  ScanInput in;
  in.choice = io::choose_isovalue(s);
  in.volume = std::move(s.volume);
  return in;
}

bool is_scene_path(const std::string& path) { return std::filesystem::path(path).extension() == ".json"; }

}  // namespace isotouch::sculpt
