// report_cmd.cpp - `isotouch report`: options only; see bench/error_report.h.
#include "isotouch/apps/report_cmd.h"

#include <iostream>
#include <memory>

#include "isotouch/bench/error_report.h"

namespace isotouch::app {

Subcommand add_report_command(CLI::App& cli) {
  auto o = std::make_shared<bench::ReportOptions>();
  CLI::App* report = cli.add_subcommand(
      "report", "Error against run time: sweep algorithm (HRI, Avila-Sobierajski, Blezek-Robb) x n x options x "
                "scene along the same strokes; write error_vs_time.csv/.png/.md");
  report->add_option("--scenes", o->scenes, "Scenes: sphere box three-spheres knot head chest, or scene JSON files")
      ->capture_default_str();
  report->add_option("--out,-o", o->out_dir, "Output folder")->capture_default_str();
  return {report, [o](const std::string& device) {
            bench::ReportOptions opt = *o;
            opt.device = device;
            return bench::run_report(opt, std::cout);
          }};
}

}  // namespace isotouch::app
