// libFuzzer target for the .seg.nrrd segment parser: the input is a NRRD header's key/value
// lines ("KEY:=VALUE", one a line); any input either gives segments that keep the parser's
// promises or throws MaterialError.
#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "isotouch/materials/material.h"
#include "isotouch/materials/seg_nrrd.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::vector<std::pair<std::string, std::string>> keys;
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t end = std::min(text.find('\n', at), text.size());
    const std::string line = text.substr(at, end - at);
    const std::size_t sep = line.find(":=");
    if (sep != std::string::npos) keys.emplace_back(line.substr(0, sep), line.substr(sep + 2));
    at = end + 1;
  }
  try {
    const auto segs = isotouch::materials::parse_seg_nrrd_segments(keys, "fuzz.seg.nrrd");
    std::set<int> values;
    std::set<std::string> names;
    for (std::size_t i = 0; i < segs.size(); ++i) {
      const auto& s = segs[i];
      if (s.index != int(i) || s.name.empty() || !names.insert(s.name).second || s.label_value < 1 ||
          s.label_value > 65535 || !values.insert(s.label_value).second || s.layer != 0)
        __builtin_trap();
      for (double c : s.color)
        if (!(c >= 0.0 && c <= 1.0)) __builtin_trap();
    }
    if (segs.empty() || segs.size() > std::size_t(isotouch::materials::kMaxSegments)) __builtin_trap();
  } catch (const isotouch::materials::MaterialError&) {
  }
  return 0;
}
