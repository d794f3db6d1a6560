// scene_field_range.h - a field's numeric range and default as the manual writes them, read
// back into numbers. The field tables (io/scene_fields.h, apps/sculpt/input_script.h) hold
// the manual's text; the parsers check values against what that text says, so a range
// changed in a table changes both what is refused and what the manual must say.
#pragma once
#include <cmath>
#include <cstdlib>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

namespace isotouch::io {

/// A numeric range: an interval "[lo, hi]", "(lo, hi]", "[lo, hi)", "(lo, hi)" or a bound
/// "> lo", ">= lo", optionally preceded by "integer " (whole numbers only).
struct FieldRange {
  double lo = 0, hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false, integer = false;
  std::string_view text;  ///< the range as written, without "integer " and any note after it

  bool contains(double d) const {
    return std::isfinite(d) && (lo_open ? d > lo : d >= lo) && (hi_open ? d < hi : d <= hi) &&
           (!integer || d == std::floor(d));
  }
  /// "in (0, 1e6]", "> 0" or "an integer in [1, 64]", for "must be ...".
  std::string phrase() const {
    return (integer ? "an integer " : "") + std::string(text[0] == '>' ? "" : "in ") + std::string(text);
  }
};

/// `text` when the whole of it is a finite number ("1e6", "-0.5"); nullopt otherwise.
inline std::optional<double> plain_number(std::string_view text) {
  const std::string s(text);
  if (s.empty() || s.find_first_of(" \t") != std::string::npos) return std::nullopt;
  char* end = nullptr;
  const double d = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || !std::isfinite(d)) return std::nullopt;
  return d;
}

/// The range `text` states, or nullopt when it is no numeric range (e.g. "true, false").
/// After the range, a note may follow a ',' or ';' ("[0, 1e6], required").
inline std::optional<FieldRange> field_range(std::string_view text) {
  FieldRange r;
  if (text.rfind("integer ", 0) == 0) {
    r.integer = true;
    text.remove_prefix(8);
  }
  std::size_t end;
  if (text.rfind("> ", 0) == 0 || text.rfind(">= ", 0) == 0) {
    r.lo_open = text[1] == ' ';
    const std::size_t from = r.lo_open ? 2 : 3;
    end = text.find_first_of(",;", from);
    const auto lo = plain_number(text.substr(from, end == std::string_view::npos ? end : end - from));
    if (!lo) return std::nullopt;
    r.lo = *lo;
  } else {
    if (text.empty() || (text[0] != '[' && text[0] != '(')) return std::nullopt;
    const std::size_t comma = text.find(", "), close = text.find_first_of("])");
    if (comma == std::string_view::npos || close == std::string_view::npos || close < comma) return std::nullopt;
    const auto lo = plain_number(text.substr(1, comma - 1)), hi = plain_number(text.substr(comma + 2, close - comma - 2));
    if (!lo || !hi) return std::nullopt;
    r.lo = *lo, r.hi = *hi, r.lo_open = text[0] == '(', r.hi_open = text[close] == ')';
    end = close + 1;
    if (end < text.size() && text[end] != ',' && text[end] != ';') return std::nullopt;
  }
  r.text = text.substr(0, end);
  return r;
}

}  // namespace isotouch::io
