#include "isotouch/io/scan.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <utility>
#include <vector>

#include "isotouch/io/dicom_series.h"
#include "isotouch/io/volume_io.h"

namespace isotouch::io {
namespace fs = std::filesystem;

std::string lower_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::string suggested_source(const LoadedVdb& l) {
  return l.grid_class == "level set" && !l.written_by_isotouch ? "level set" : ".vdb metadata";
}

namespace {
bool is_nrrd_name(const std::string& path) {
  const std::string ext = lower_extension(path);
  return ext == ".nrrd" || ext == ".nhdr";
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  const auto e = s.find_last_not_of(" \t\r");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

/// The words of a header's text, lower case, split at anything but letters and digits.
std::vector<std::string> words(const std::string& text) {
  std::vector<std::string> out;
  std::string w;
  for (const char ch : text + " ") {
    if (std::isalnum(static_cast<unsigned char>(ch))) w += char(std::tolower(static_cast<unsigned char>(ch)));
    else if (!w.empty()) out.push_back(w), w.clear();
  }
  return out;
}
}  // namespace

void read_text_hints(const std::string& format, const std::vector<std::pair<std::string, std::string>>& fields,
                     engine::VolumeHints& hints) {
  for (const auto& [field, value] : fields) {
    const std::vector<std::string> w = words(value);
    const auto has = [&](const std::string& x) { return std::find(w.begin(), w.end(), x) != w.end(); };
    const auto has_pair = [&](const std::string& a, const std::string& b) {
      for (std::size_t i = 0; i + 1 < w.size(); ++i)
        if (w[i] == a && w[i + 1] == b) return true;
      return false;
    };
    const std::string from = format + " " + field + " '" + value.substr(0, 60) + "'";
    if (hints.modality.empty() && (has("ct") || has_pair("computed", "tomography")))
      hints.modality = "CT", hints.modality_from = from;
    if (hints.units.empty() && (has("hu") || has("hounsfield"))) hints.units = "HU", hints.units_from = from;
  }
}

std::string metaimage_modality(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext != ".mhd" && ext != ".mha") return "";
  std::ifstream in(path, std::ios::binary);
  std::string line;
  // A header is a few dozen short lines; an .mha's binary data follows ElementDataFile.
  for (int n = 0; n < 200 && std::getline(in, line); ++n) {
    const auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    const std::string key = trim(line.substr(0, eq)), value = trim(line.substr(eq + 1));
    if (key == "ElementDataFile") break;
    if (key == "Modality") return value.rfind("MET_MOD_", 0) == 0 ? value.substr(8) : value;
  }
  return "";
}

Scan load_scan(const std::string& path) {
  Scan s;
  std::error_code ec;
  if (lower_extension(path) == ".vdb") {
    LoadedVdb l = load_vdb(path);
    s.volume = std::move(l.volume);
    if (l.suggested) {
      s.hints.stored = l.suggested;
      s.hints.stored_from = suggested_source(l);
    }
  } else if (fs::is_directory(path, ec)) {
    DicomSeriesInfo info;
    s.volume = load_dicom_series(path, "", &info);
    for (const auto& note : info.notes) std::cerr << "isotouch: note: " << path << ": " << note << "\n";
    s.hints.modality = info.modality;
  } else {
    s.volume = load_volume(path);
    s.hints.modality = metaimage_modality(path);
    // NIfTI and NRRD have no modality field: their description and key/value text may say it.
    if (s.hints.modality.empty())
      read_text_hints(is_nrrd_name(path) ? "NRRD" : "NIfTI", header_text_fields(path), s.hints);
  }
  return s;
}

}  // namespace isotouch::io
