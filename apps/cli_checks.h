// cli_checks.h - CLI11 validators whose messages give readable bounds.
#pragma once
#include <cmath>
#include <string>

#include <CLI/CLI.hpp>

namespace isotouch::app {

/// A finite number > 0. Message: "must be a finite number > 0, got 0".
inline CLI::Validator positive_number() {
  return CLI::Validator(
      [](std::string& s) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(s, v) || !std::isfinite(v) || !(v > 0))
          return "must be a finite number > 0, got " + s;
        return "";
      },
      "POSITIVE");
}

/// A finite number >= 0. Message: "must be a finite number >= 0, got -1".
inline CLI::Validator non_negative_number() {
  return CLI::Validator(
      [](std::string& s) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(s, v) || !std::isfinite(v) || !(v >= 0))
          return "must be a finite number >= 0, got " + s;
        return "";
      },
      "NONNEGATIVE");
}

/// Any finite number. Message: "must be a finite number, got nan" (also for inf and for
/// 1e400, past the largest double), with `what` after it when given.
inline CLI::Validator finite_number(const std::string& what = "") {
  return CLI::Validator(
      [what](std::string& s) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(s, v) || !std::isfinite(v))
          return "must be a finite number" + (what.empty() ? std::string() : " (" + what + ")") + ", got " + s;
        return "";
      },
      "NUMBER");
}

}  // namespace isotouch::app
