// stability_cmd.cpp - `isotouch stability`: options only; see bench/stability_report.h.
#include "isotouch/apps/stability_cmd.h"

#include <iostream>
#include <memory>
#include <string>

#include "isotouch/bench/link_stability.h"
#include "isotouch/bench/stability_report.h"

namespace isotouch::app {

Subcommand add_stability_command(CLI::App& cli) {
  struct Options {
    std::string out = "out/stability";
    bool quick = false;
    std::string scene;
  };
  auto o = std::make_shared<Options>();
  CLI::App* stab = cli.add_subcommand(
      "stability", "Measure the largest stable stiffness K_max against Colgate-Schenkel's bound 2(b-|B|)/T "
                   "(T = 1, 0.25, 0.1 ms; several b), with and without the passivity controller, and run the "
                   "extreme cases; then a wall through a delayed link: K_max against round trip (0-20 ms) and "
                   "link rate (100-1000 Hz), with and without the passivity controller at the device end; write "
                   "stability.csv, extreme_cases.csv, stability.png, stability.md, link_stability.csv, "
                   "link_stability.md");
  stab->add_option("--out,-o", o->out, "Output folder")->capture_default_str();
  stab->add_flag("--quick", o->quick, "Shorter runs and coarser search (for tests)");
  stab->add_option("--scene", o->scene,
                   "Also sweep the delayed link on this scene's scan (e.g. scenes/head.json: presses on the skull "
                   "where its script's ray meets it); writes link_stability_scene.csv, link_stability_scene.md")
      ->check(CLI::ExistingFile);
  return {stab, [o](const std::string&) {
            const int rc = bench::run_stability(o->out, o->quick, std::cout);
            const int rc_link = bench::run_link_stability(o->out, o->quick, std::cout);
            const int rc_scene = o->scene.empty() ? 0 : bench::run_link_stability_on_scene(o->scene, o->out, o->quick, std::cout);
            return rc != 0 ? rc : rc_link != 0 ? rc_link : rc_scene;
          }};
}

}  // namespace isotouch::app
