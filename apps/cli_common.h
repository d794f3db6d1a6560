// cli_common.h - what every isotouch program's command line shares (isotouch,
// isotouch-sculpt, isotouch-devemu): the help's look, --version and the usage exit code.
#pragma once
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "isotouch/core/exit_codes.h"
#include "isotouch/version.h"

namespace isotouch::app {

/// CLI11's help with switches named plainly: "--no-overlay", not "--no-overlay{false}"
/// (the flag value CLI11 appends reads as if the switch were off by default; each
/// switch's text says its default).
class HelpFormatter : public CLI::Formatter {
 public:
  std::string make_option_name(const CLI::Option* opt, bool positional) const override {
    std::string name = CLI::Formatter::make_option_name(opt, positional);
    for (std::size_t open = name.find('{'); open != std::string::npos; open = name.find('{', open)) {
      const std::size_t close = name.find('}', open);
      if (close == std::string::npos) break;
      name.erase(open, close - open + 1);
    }
    return name;
  }
};

/// The look and the --version flag every isotouch program shares; call before adding
/// subcommands (they copy the formatter). `--version` prints "isotouch X.Y.Z" and exits 0.
inline void common_options(CLI::App& app) {
  app.formatter(std::make_shared<HelpFormatter>());
  app.set_version_flag("--version", std::string("isotouch ") + kVersion, "Print the version (isotouch X.Y.Z) and exit");
}

/// After CLI::App::parse threw: prints what CLI11 prints (the help, the version, or the
/// error with its option) and returns the exit status: 0 for --help / --version,
/// exit_code::kUsage for a usage error (CLI11's own codes, 105 and up, are not used).
inline int parse_exit(const CLI::App& app, const CLI::ParseError& e) {
  const int cli11 = app.exit(e);
  return cli11 == 0 ? exit_code::kOk : exit_code::kUsage;
}

}  // namespace isotouch::app
