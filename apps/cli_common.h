// cli_common.h - what every isotouch program's command line shares (isotouch,
// isotouch-sculpt, isotouch-devemu): the help's look, --version and the usage exit code.
#pragma once
#include <memory>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>

#include "isotouch/core/exit_codes.h"
#include "isotouch/version.h"

namespace isotouch::app {

/// `text` with every line longer than `width` broken at spaces; a broken line's rest keeps
/// that line's leading spaces. Newlines already in it stay.
inline std::string wrap_text(const std::string& text, std::size_t width) {
  std::string out;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(start, end - start);
    const std::string indent = line.substr(0, line.find_first_not_of(' ') == std::string::npos ? 0 : line.find_first_not_of(' '));
    while (line.size() > width) {
      std::size_t cut = line.rfind(' ', width);
      if (cut == std::string::npos || cut <= indent.size()) cut = line.find(' ', width);
      if (cut == std::string::npos) break;
      out += line.substr(0, cut) + "\n";
      line = indent + line.substr(line.find_first_not_of(' ', cut) == std::string::npos ? line.size() : line.find_first_not_of(' ', cut));
    }
    out += line;
    if (end == text.size()) break;
    out += "\n";
    start = end + 1;
  }
  return out;
}

/// CLI11's help with switches named plainly: "--no-overlay", not "--no-overlay{false}"
/// (the flag value CLI11 appends reads as if the switch were off by default; each
/// switch's text says its default), and every line within kHelpWidth columns (descriptions
/// wrapped at spaces under their column).
class HelpFormatter : public CLI::Formatter {
 public:
  static constexpr std::size_t kHelpWidth = 100;
  std::string make_option_desc(const CLI::Option* opt) const override {
    return wrap_text(CLI::Formatter::make_option_desc(opt), desc_width());
  }
  std::string make_subcommand(const CLI::App* sub) const override {
    std::stringstream out;
    CLI::detail::format_help(out, sub->get_display_name(true), wrap_text(sub->get_description(), desc_width()),
                             get_column_width());
    return out.str();
  }
  std::string make_description(const CLI::App* app) const override {
    return wrap_text(CLI::Formatter::make_description(app), kHelpWidth);
  }
  std::string make_footer(const CLI::App* app) const override {
    return wrap_text(CLI::Formatter::make_footer(app), kHelpWidth);
  }
  std::string make_option_name(const CLI::Option* opt, bool positional) const override {
    std::string name = CLI::Formatter::make_option_name(opt, positional);
    for (std::size_t open = name.find('{'); open != std::string::npos; open = name.find('{', open)) {
      const std::size_t close = name.find('}', open);
      if (close == std::string::npos) break;
      name.erase(open, close - open + 1);
    }
    return name;
  }

 private:
  std::size_t desc_width() const { return kHelpWidth > get_column_width() + 20 ? kHelpWidth - get_column_width() : 20; }
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
