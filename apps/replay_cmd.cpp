// replay_cmd.cpp - STUB (lead) until the record-replay helper fills it in.
#include "replay_cmd.h"

#include <iostream>

namespace isotouch::app {

Subcommand add_replay_command(CLI::App& cli) {
  auto* sub = cli.add_subcommand("replay", "Play a recording (run --record) back and check the forces");
  auto file = std::make_shared<std::string>();
  sub->add_option("file", *file, "Recording file")->required();
  return {sub, [file](const std::string&) {
            std::cerr << "isotouch replay: not implemented yet\n";
            return 2;
          }};
}

}  // namespace isotouch::app
