// text.h - how the run job writes a number into its log, report and notes.
#pragma once
#include <iomanip>
#include <sstream>
#include <string>

namespace isotouch::run {

/// `v` with `prec` significant digits (the stream's default notation).
inline std::string fmt(double v, int prec = 6) {
  std::ostringstream s;
  s << std::setprecision(prec) << v;
  return s.str();
}

}  // namespace isotouch::run
