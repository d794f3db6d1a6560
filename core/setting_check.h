// setting_check.h - refuse a numeric setting by name and value (std::invalid_argument).
#pragma once
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace isotouch::core {

/// Throws std::invalid_argument "<owner>: <field> = <value> (<rule>)" unless `ok`.
inline void require_setting(bool ok, const char* owner, const char* field, double value, const char* rule) {
  if (ok) return;
  std::ostringstream m;
  m << owner << ": " << field << " = " << value << " (" << rule << ")";
  throw std::invalid_argument(m.str());
}

/// Finite and > 0.
inline void require_positive(const char* owner, const char* field, double value, const char* unit) {
  require_setting(std::isfinite(value) && value > 0, owner, field, value,
                  (std::string("must be finite and > 0 ") + unit).c_str());
}

/// Finite and >= 0.
inline void require_non_negative(const char* owner, const char* field, double value, const char* unit) {
  require_setting(std::isfinite(value) && value >= 0, owner, field, value,
                  (std::string("must be finite and >= 0 ") + unit).c_str());
}

}  // namespace isotouch::core
