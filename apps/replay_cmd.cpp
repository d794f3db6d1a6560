// replay_cmd.cpp - `isotouch replay FILE`: options and exit codes; the replay is run/replay.h.
#include "isotouch/apps/replay_cmd.h"

#include "isotouch/core/exit_codes.h"

#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>

#include "isotouch/io/record.h"
#include "isotouch/run/replay.h"
#include "isotouch/io/scene.h"

namespace isotouch::app {
namespace fs = std::filesystem;

Subcommand add_replay_command(CLI::App& cli) {
  struct Args {
    std::string file, out;
    bool quiet = false;
  };
  auto a = std::make_shared<Args>();
  auto* sub = cli.add_subcommand(
      "replay",
      "Play a recording (run --record) back through the same renderer and edits and check every force, VHIP\n"
      "and snapshot version bit for bit (format 1 recordings: forces only).\n"
      "Exit 0: identical; 1: something differs (the first differing tick is printed); 2: bad input (unreadable\n"
      "recording, the scene file or the volume changed) or a usage error; 3: the pipeline could not run.");
  sub->add_option("file", a->file, "Recording file (isotouch run SCENE --record FILE)")->required();
  sub->add_option("--out", a->out, "Also write the replay's trace.csv (recorded and replayed forces) into DIR");
  sub->add_flag("--quiet", a->quiet, "No progress lines");
  return {sub, [a](const std::string& device) {
            run::ReplayOptions opt;
            opt.out_dir = a->out;
            opt.device = device;
            opt.progress = !a->quiet;
            opt.name = a->file;
            opt.recording_dir = fs::path(a->file).parent_path().string();
            if (opt.recording_dir.empty()) opt.recording_dir = ".";
            run::ReplayResult r;
            int rec_format = 0;
            try {
              // A live session's recording may be cut short (FILE.part after a crash): replayed
              // up to its last whole line.
              const io::Recording rec = io::load_recording(a->file, /*allow_incomplete=*/true);
              rec_format = rec.format_version;
              if (!rec.complete)
                std::cout << "isotouch replay: " << a->file << " has no end record (the live session did not stop "
                          << "cleanly): replaying the " << rec.ticks.size() << " ticks written before the cut\n";
              std::cout << "isotouch replay: " << a->file << ": " << rec.ticks.size() << " ticks, " << rec.edits.size()
                        << " edits at " << rec.rate_hz << " Hz, scene " << rec.scene_path << "\n";
              std::ostringstream setup_log;
              r = run::replay_recording(rec, opt, a->quiet ? static_cast<std::ostream&>(setup_log) : std::cout);
            } catch (const io::RecordingError& e) {
              std::cerr << "isotouch replay: " << e.what() << "\n";
              std::error_code ec;
              if (!fs::exists(a->file, ec) && fs::is_regular_file(a->file + ".part", ec))
                std::cerr << "isotouch replay: " << a->file << ".part exists: the live session that wrote it did not "
                          << "stop cleanly; replay that file (up to its last chunk)\n";
              return exit_code::kReplayBadInput;
            } catch (const run::ReplayInputError& e) {
              std::cerr << "isotouch replay: " << e.what() << "\n";
              return exit_code::kReplayBadInput;
            } catch (const io::SceneError& e) {
              std::cerr << "isotouch replay: the recorded scene: " << e.what() << "\n";
              return exit_code::kReplayBadInput;
            } catch (const std::exception& e) {
              std::cerr << "isotouch replay: " << a->file << ": could not run the pipeline: " << e.what() << "\n";
              return exit_code::kReplayCannotRun;
            }
            std::cout << "replayed " << r.ticks << " ticks, " << r.edits << " edits (" << r.publications
                      << " snapshots published); max |dF| " << std::setprecision(6) << r.max_df_n << " N\n";
            if (r.cut_ticks > 0)
              std::cout << "isotouch replay: the last " << r.cut_ticks << " ticks read a snapshot whose edit was "
                        << "written after the cut: not compared\n";
            if (!a->out.empty()) std::cout << "trace    " << (fs::path(a->out) / "trace.csv").string() << "\n";
            std::cout << run::replay_verdict(r, rec_format);
            return r.identical() ? exit_code::kOk : exit_code::kReplayDiffers;
          }};
}

}  // namespace isotouch::app
