// subcommand.h - how a command module hooks into the isotouch command line.
// A module defines `Subcommand add_X(CLI::App& parent)`: it adds its CLI11 subcommand with
// its own options (kept in the module), and returns the function main() calls when that
// subcommand was parsed. main.cpp stays a list of these calls.
#pragma once
#include <CLI/CLI.hpp>
#include <functional>
#include <string>

namespace isotouch::app {

struct Subcommand {
  CLI::App* app = nullptr;
  /// Runs the parsed subcommand. @param device the global --device option (may be empty).
  /// @return the process exit code.
  std::function<int(const std::string& device)> run;
};

}  // namespace isotouch::app
