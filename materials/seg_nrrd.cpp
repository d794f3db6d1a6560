#include "isotouch/materials/seg_nrrd.h"

#include <charconv>
#include <map>
#include <set>
#include <sstream>

#include "isotouch/materials/material.h"

namespace isotouch::materials {
namespace {

const char* const kFields[] = {"Name", "LabelValue", "Layer", "Color"};

[[noreturn]] void fail(const std::string& path, const std::string& key, const std::string& what) {
  throw MaterialError(path + ": header key '" + key + "': " + what);
}

/// "SegmentN_FIELD" -> (N, FIELD); false for keys of other forms. A key shaped like a segment's,
/// "Segment" then a sign or digit up to '_', whose N is not a plain decimal in range (a sign,
/// a leading zero, too many digits) is an error: skipping it would drop a segment silently,
/// and "Segment01_" would be read as segment 1.
bool split_key(const std::string& path, const std::string& key, long& index, std::string& field) {
  constexpr std::string_view kPrefix = "Segment";
  if (key.size() <= kPrefix.size() || key.compare(0, kPrefix.size(), kPrefix) != 0) return false;
  const std::size_t us = key.find('_', kPrefix.size());
  if (us == std::string::npos || us == kPrefix.size()) return false;
  const std::string n = key.substr(kPrefix.size(), us - kPrefix.size());
  if (n.find_first_not_of("+-0123456789") != std::string::npos) return false;
  const char* e = n.data() + n.size();
  const auto [p, ec] = std::from_chars(n.data(), e, index);
  if (ec != std::errc() || p != e || index < 0 || (n.size() > 1 && n[0] == '0'))
    fail(path, key, "segment index \"" + n + "\" is not a whole number 0 to " + std::to_string(kMaxSegments - 1) +
                        " written plainly");
  field = key.substr(us + 1);
  return true;
}

/// The whole of `text` as an integer in [lo, hi].
bool whole_int(const std::string& text, long lo, long hi, int& out) {
  long v = 0;
  const char* e = text.data() + text.size();
  const auto [p, ec] = std::from_chars(text.data(), e, v);
  if (ec != std::errc() || p != e || v < lo || v > hi) return false;
  out = int(v);
  return true;
}

/// "R G B", three numbers in [0, 1] and nothing else.
bool color3(const std::string& text, std::array<double, 3>& rgb) {
  std::istringstream in(text);
  in.imbue(std::locale::classic());
  for (double& c : rgb)
    if (!(in >> c) || !(c >= 0.0 && c <= 1.0)) return false;
  std::string rest;
  return !(in >> rest);
}

}  // namespace

std::vector<Segment> parse_seg_nrrd_segments(const std::vector<std::pair<std::string, std::string>>& keys,
                                             const std::string& path) {
  std::map<long, std::map<std::string, std::string>> by_index;
  for (const auto& [key, value] : keys) {
    long n = 0;
    std::string field;
    if (!split_key(path, key, n, field)) continue;
    if (n >= kMaxSegments) fail(path, key, "segment index " + std::to_string(n) + " above " + std::to_string(kMaxSegments - 1));
    if (!by_index[n].emplace(field, value).second) fail(path, key, "given twice");
  }
  if (by_index.empty())
    fail(path, "Segment0_Name", "missing: no SegmentN_ keys, not a 3D Slicer segmentation (give a label map instead)");
  std::vector<Segment> out;
  std::set<std::string> names;
  std::set<int> values;
  for (long n = 0; n <= by_index.rbegin()->first; ++n) {
    const std::string pre = "Segment" + std::to_string(n) + "_";
    const auto& f = by_index[n];
    for (const char* k : kFields)
      if (!f.count(k)) fail(path, pre + k, "missing (every segment needs _Name, _LabelValue, _Layer and _Color)");
    Segment s;
    s.index = int(n);
    s.name = f.at("Name");
    if (s.name.empty() || !names.insert(s.name).second)
      fail(path, pre + "Name", "\"" + s.name + "\" is empty or names an earlier segment too");
    const std::string& lv = f.at("LabelValue");
    if (!whole_int(lv, 1, 65535, s.label_value)) fail(path, pre + "LabelValue", "must be an integer in [1, 65535], got \"" + lv + "\"");
    if (!values.insert(s.label_value).second) fail(path, pre + "LabelValue", lv + " is an earlier segment's label value too");
    const std::string& ly = f.at("Layer");
    if (!whole_int(ly, 0, 65535, s.layer)) fail(path, pre + "Layer", "must be an integer >= 0, got \"" + ly + "\"");
    if (s.layer != 0)
      fail(path, pre + "Layer", ly + ": overlapping segments in several layers are not read (export a label map from 3D Slicer)");
    if (!color3(f.at("Color"), s.color)) fail(path, pre + "Color", "must be \"R G B\", each in [0, 1], got \"" + f.at("Color") + "\"");
    out.push_back(s);
  }
  return out;
}

}  // namespace isotouch::materials
