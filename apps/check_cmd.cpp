// check_cmd.cpp - `isotouch check VOLUME` and `isotouch check --all`: options only; the
// checks are bench/pass_check.
#include "isotouch/apps/check_cmd.h"

#include <iostream>
#include <memory>
#include <string>

#include "isotouch/bench/pass_check.h"

namespace isotouch::app {
namespace {
struct CheckOptions {
  std::string volume;
  double slab_mib = 0;
  bool all = false;
  bench::CheckAllOptions all_options;
};
}  // namespace

Subcommand add_check_command(CLI::App& cli) {
  CLI::App* check = cli.add_subcommand(
      "check", "Compare the GPU gradient with the CPU reference on a volume; with --all, every engine pass "
               "(Gaussian, closing, gradient, brick min/max) against its CPU reference and OpenVDB");
  auto o = std::make_shared<CheckOptions>();
  check->add_option("volume", o->volume,
                    "Volume file (.mhd, .mha, .nrrd, .nhdr, .nii, .nii.gz, .vdb) or DICOM series folder (its slices; "
                    "with several series, the one with the most slices); not with --scene");
  check->add_flag("--all", o->all,
                  "Every pass (gaussian 1 mm, closing 1 mm, gradient, brick_minmax) on the GPU against its "
                  "one-thread CPU reference, the gradient against OpenVDB too: a table of max abs/relative "
                  "difference, ULP max/p99, non-identical and NaN/Inf counts, GPU and CPU time. Exit 3 on "
                  "disagreement (bit identity on a CPU device such as lavapipe, 64 ULP elsewhere)");
  check->add_option("--scene", o->all_options.scene_path,
                    "With --all: the scene's volume and isovalue (passes: the default list)");
  check->add_flag("--validation", o->all_options.validation,
                  "With --all: Vulkan validation layer on (also ISOTOUCH_VALIDATION=1); any message fails the check");
  // Debug only, hidden: proves the comparison can fail (moves one CPU Gaussian value by 1000 ULP).
  check->add_flag("--inject-mismatch", o->all_options.inject_mismatch)->group("");
  check->add_option("--max-binding-mib", o->slab_mib,
                    "Limit storage-buffer bindings to this size (forces z-slabs; default: device limit)")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            double v = 0;
            std::size_t used = 0;
            try {
              v = std::stod(text, &used);
            } catch (const std::exception&) {
              used = 0;
            }
            if (used != text.size() || !(v > 0.0 && v <= 1048576.0))
              return "must be a number of MiB in (0, 1048576], got " + text;
            return {};
          },
          "MiB in (0, 1048576]"));
  // Combinations CLI11 cannot express, refused while parsing (usage errors, as CLI11's own).
  check->callback([o] {
    if (!o->all && (!o->all_options.scene_path.empty() || o->all_options.validation || o->all_options.inject_mismatch))
      throw CLI::ValidationError("--scene, --validation and --inject-mismatch need --all");
    if (!o->all && o->volume.empty()) throw CLI::RequiredError("volume");
    if (o->all && o->volume.empty() == o->all_options.scene_path.empty())
      throw CLI::ValidationError("check --all: give a VOLUME file or --scene SCENE, one of them");
  });
  return {check, [o](const std::string& device) {
            if (!o->all) return bench::run_check_gradient(o->volume, device, o->slab_mib, std::cout);
            bench::CheckAllOptions c = o->all_options;
            c.volume_path = o->volume;
            c.device = device;
            c.max_binding_mib = o->slab_mib;
            return bench::run_check_all(c, std::cout);
          }};
}

}  // namespace isotouch::app
