// sweep_cmd.cpp - `isotouch sweep`: hands its arguments to the Python sweep (Dask), which does
// the work through the isotouch module; this command only finds the interpreter and the module.
#include "isotouch/apps/sweep_cmd.h"

#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "isotouch/core/exit_codes.h"

namespace isotouch::app {
namespace {

namespace fs = std::filesystem;

/// The folder to put on PYTHONPATH: the build tree's BUILD/python beside BUILD/bin, or an
/// installation's PREFIX/lib/python3/dist-packages beside PREFIX/bin; empty if neither holds
/// isotouch/sweep.py (then `tried` lists where it looked).
std::string module_dir(std::string& tried) {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return {};
  for (const fs::path& d : {exe.parent_path().parent_path() / "python",
                            exe.parent_path().parent_path() / "lib/python3/dist-packages"}) {
    if (fs::exists(d / "isotouch" / "sweep.py", ec)) return d.string();
    tried += (tried.empty() ? "" : ", ") + (d / "isotouch" / "sweep.py").string();
  }
  return {};
}

/// $ISOTOUCH_PYTHON, else Debian's /usr/bin/python3 (the interpreter the module is built for),
/// else python3 on PATH.
std::string interpreter() {
  if (const char* p = std::getenv("ISOTOUCH_PYTHON"); p && *p) return p;
  if (access("/usr/bin/python3", X_OK) == 0) return "/usr/bin/python3";
  return "python3";
}

int exec_sweep(const std::vector<std::string>& args) {
  std::string tried;
  const std::string dir = module_dir(tried);
  if (dir.empty()) {
    std::cerr << "isotouch sweep: the isotouch Python module was not found (looked for " << tried
              << "); build it (python/, needs pybind11-dev python3-dev python3-numpy) or install it\n";
    return exit_code::kError;
  }
  const char* old = std::getenv("PYTHONPATH");
  const std::string path = dir + (old && *old ? ":" + std::string(old) : "");
  setenv("PYTHONPATH", path.c_str(), 1);
  setenv("ISOTOUCH_SWEEP_PROG", "isotouch sweep", 1);  // its usage names this command
  const std::string python = interpreter();
  std::vector<std::string> argv_s = {python, "-m", "isotouch.sweep"};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  execvp(python.c_str(), argv.data());
  std::cerr << "isotouch sweep: cannot run " << python << ": " << std::strerror(errno)
            << " (set ISOTOUCH_PYTHON to the python3 the module was built for)\n";
  return exit_code::kError;
}

}  // namespace

Subcommand add_sweep_command(CLI::App& cli) {
  Subcommand s;
  s.app = cli.add_subcommand("sweep",
                             "Error against run time over scans x methods x parameter grids on a Dask cluster "
                             "(local workers, a scheduler, Slurm): runs `python3 -m isotouch.sweep` with "
                             "every argument after `sweep` (`isotouch sweep --help`; docs/sweeps.md)");
  s.app->prefix_command();
  s.app->allow_extras();
  s.app->fallthrough(false);  // the global options are not taken out of the sweep's arguments
  s.app->set_help_flag();  // --help goes to the sweep's own parser
  s.run = [app = s.app](const std::string&) { return exec_sweep(app->remaining()); };
  return s;
}

}  // namespace isotouch::app
