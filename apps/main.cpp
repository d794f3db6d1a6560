// isotouch - feel the isosurface inside a volume through a point haptic device (HRI).
// main() is the list of commands: each is one file in apps/ (its options), and the work
// it runs lives in the library folders (run/, bench/, io/, ...).
#include <CLI/CLI.hpp>

#include <iostream>
#include <vector>

#include "isotouch/apps/bench_cmd.h"
#include "isotouch/apps/check_cmd.h"
#include "isotouch/apps/cli_common.h"
#include "isotouch/apps/devices_cmd.h"
#include "isotouch/apps/export_cmd.h"
#include "isotouch/apps/render_cmd.h"
#include "isotouch/apps/replay_cmd.h"
#include "isotouch/apps/report_cmd.h"
#include "isotouch/apps/run_cmd.h"
#include "isotouch/apps/serve_cmd.h"
#include "isotouch/apps/stability_cmd.h"
#include "isotouch/apps/subcommand.h"
#include "isotouch/apps/sweep_cmd.h"

using namespace isotouch;

int main(int argc, char** argv) {
  CLI::App cli{
      "isotouch: feel the isosurface inside a volume (CT, MR, sculpted) through a point haptic\n"
      "device with the HRI servo (intermediate virtual plane), from samples a Vulkan compute\n"
      "shader precomputed.\n\n"
      "Examples:\n"
      "  isotouch run                          # default scene scenes/head.json -> out/head/\n"
      "  isotouch run scenes/chest.json --out /tmp/chest\n"
      "  isotouch check data/ct-tooth/tooth.nhdr\n"
      "  isotouch check data/ct-chest-lungdx-a0001/dicom-5mm   # a DICOM series folder\n"
      "  isotouch serve scenes/head.json       # OpenIGTLink server for 3D Slicer / PLUS (port 18944)\n"
      "  isotouch sweep python/sweeps/report.json --local-workers 2   # Dask sweep -> sweep-out/\n"
      "  ISOTOUCH_DEVICE=llvmpipe isotouch run # choose the Vulkan device\n\n"
      "Exit status: 0 ok, 1 bad input or error, 2 usage error, 3 a check failed, 4 servo faults,\n"
      "5 haptic device lost, 128 + N stopped by signal N; each command's --help says which it uses\n"
      "(docs/exit-codes.md has the table)."};
  app::common_options(cli);
  cli.require_subcommand(1);
  // Options of the main command (--device) are accepted after the subcommand too:
  // `isotouch run scenes/x.json --device llvmpipe`. Inherited by every subcommand.
  cli.fallthrough();
  std::string device;
  cli.add_option("--device", device,
                 "Vulkan device: name substring or index (default: $ISOTOUCH_DEVICE, else the first "
                 "discrete GPU, else lavapipe); `cpu`: run and replay on the CPU backend (the engine chain on up "
                 "to 8 threads, brushes and pictures by the CPU references: the same bits as on lavapipe; also "
                 "taken when no device was asked for and no Vulkan device opens); before or after the subcommand");

  std::vector<app::Subcommand> commands = {app::add_run_command(cli), app::add_check_command(cli),
                                           app::add_devices_command(cli), app::add_stability_command(cli),
                                           app::add_report_command(cli)};
  for (app::Subcommand& b : app::add_bench_commands(cli)) commands.push_back(std::move(b));
  for (app::Subcommand c : {app::add_render_command(cli), app::add_export_command(cli), app::add_replay_command(cli),
                            app::add_serve_command(cli), app::add_sweep_command(cli)})
    commands.push_back(std::move(c));

  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app::parse_exit(cli, e);
  }
  try {
    for (const app::Subcommand& c : commands)
      if (c.app->parsed()) return c.run(device);
    std::cerr << "isotouch: no command given (see --help)\n";
    return exit_code::kUsage;
  } catch (const std::exception& e) {
    std::cerr << "\nisotouch: error: " << e.what() << "\n";
    return exit_code::kError;
  }
}
