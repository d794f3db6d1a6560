// serve_cmd.cpp - `isotouch serve SCENE`: options and exit codes; the server is service/serve.h.
#include "isotouch/apps/serve_cmd.h"

#include <cstdlib>
#include <iostream>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "isotouch/core/exit_codes.h"
#include "isotouch/io/scene.h"
#include "isotouch/service/serve.h"

namespace isotouch::app {

namespace {
constexpr const char* kHelp =
      "Serve SCENE over OpenIGTLink (3D Slicer's OpenIGTLinkIF, PLUS, any OpenIGTLink client), several clients\n"
      "at once. The session starts on the scene's volume, isovalue, passes and HRI parameters.\n"
      "In:  IMAGE (3-D, one scalar: int8..float64, any spacing and orientation, RAS or LPS): the session's new\n"
      "     volume, in the same physical place as the file it came from (single slices, sub-volumes, label\n"
      "     maps refused), at the isovalue a client set (`isovalue V`, while inside its values), else at its own\n"
      "     as `isotouch run VOLUME` chooses it (said in the STATUS and the log); TRANSFORM named --stream:\n"
      "     the device (translation in mm, RAS, plus --offset-mm; one client's at a time: the first, until it\n"
      "     stops for --stale-ms or goes; another's get a STATUS);\n"
      "     no TRANSFORM for --stale-ms: zero force; STRING commands: isovalue V | tool KIND [RADIUS_MM\n"
      "     [STRENGTH]] | apply | stop | undo | redo | save NAME (into --save-dir), each answered with a STATUS;\n"
      "     LBMETA: the images it names are label maps: such an IMAGE on the volume's grid becomes the session's\n"
      "     materials (the drill cuts per material; a scene material of the same name lends its fields).\n"
      "     What is refused is answered with a STATUS\n"
      "     saying why; wrong CRC, truncated or oversized bodies and unknown types never stop the server.\n"
      "Out: TRANSFORMs 'HIP' and 'Proxy' (translation in mm, RAS; only while a fresh pose is rendered) and\n"
      "     'Force' (translation = force in N, RAS: PLUS's convention; zero when the servo stops writing) at\n"
      "     --display-hz to every client; the edited\n"
      "     voxels as an IMAGE (the changed sub-volume, or --image-whole) at most --image-hz times a second\n"
      "     to the clients that sent an IMAGE or a command.\n"
      "Device: the TRANSFORM stream (above), or with --haptic SPEC a device of `isotouch run --live`'s factory\n"
      "     (igtl:HOST:PORT[:STREAM] a PlusServer's stylus, openhaptics[:NAME], forcedimension[:INDEX], emu:SOCKET,\n"
      "     hid:..., polhem:..., null, playback:FILE; docs/devices.md): the HIP is the device's (device [m] times the\n"
      "     scene's workspace_scale, at the volume's centre, as `run --live` maps it), the force goes to it through\n"
      "     the servo's safety gate and the device's stall rule, its stale timeout is its own; clients still get\n"
      "     the HIP, Proxy and Force TRANSFORMs and send IMAGEs and commands. An igtl: device's rate is measured\n"
      "     (1 s) and a scene stiffer than its Colgate-Schenkel bound refused unless --allow-unstable-stiffness.\n"
      "Exit 0 after --seconds; 1 bad input (scene, port, a device that cannot be opened or refuses the scene);\n"
      "2 usage error; 4 servo faults; 5 the --haptic device was disconnected, faulty or sent refused reports (the\n"
      "server went on serving); 6 a save command could not write (the session went on); 128 + N on signal N.";
/// ISOTOUCH_SERVE_TEST_FAULT="WHERE[:IMAGE],...": each entry makes the server fail once at
/// WHERE (ServeOptions::fault_for_test), for the image named IMAGE (a trailing '*': any name
/// it begins) or any: what the serve tests use to reach the failures a CPU Vulkan driver does
/// not produce.
/// Whether a test fault's IMAGE `pattern` names `image` (empty: any; "NAME*": any beginning NAME).
bool names(const std::string& pattern, const std::string& image) {
  if (!pattern.empty() && pattern.back() == '*') return image.rfind(pattern.substr(0, pattern.size() - 1), 0) == 0;
  return pattern.empty() || pattern == image;
}

std::function<bool(const std::string&, const std::string&)> test_faults(const std::string& spec) {
  struct Entry {
    std::string where, image;
    bool fired = false;
  };
  auto entries = std::make_shared<std::vector<Entry>>();
  std::istringstream in(spec);
  for (std::string e; std::getline(in, e, ',');) {
    const auto colon = e.find(':');
    entries->push_back({e.substr(0, colon), colon == std::string::npos ? "" : e.substr(colon + 1)});
  }
  auto mu = std::make_shared<std::mutex>();
  return [entries, mu](const std::string& where, const std::string& image) {
    std::lock_guard<std::mutex> lock(*mu);
    for (Entry& e : *entries)
      if (!e.fired && e.where == where && names(e.image, image)) return e.fired = true;
    return false;
  };
}
}  // namespace

Subcommand add_serve_command(CLI::App& cli) {
  struct Args {
    std::string scene;
    service::ServeOptions o;
    std::vector<double> offset;
    std::string registration;
    double stale_ms = 100;
    bool allow_unstable = false;
    std::string restore = "yes";
  };
  auto a = std::make_shared<Args>();
  auto* sub = cli.add_subcommand("serve", kHelp);
  sub->add_option("scene", a->scene, "Scene JSON (its volume, isovalue, passes, HRI parameters)")->required();
  sub->add_option("--port", a->o.port, "TCP port (default 18944, Slicer's; 0: any free port, printed)")
      ->check(CLI::Range(0, 65535));
  sub->add_option("--host", a->o.host, "Address to listen on (default 127.0.0.1: this machine only; 0.0.0.0: every interface,\n"
                  "with no authentication: any host that reaches the port can replace the volume and move the HIP)");
  auto* haptic = sub->add_option("--haptic", a->o.haptic,
                                 "The haptic device instead of the TRANSFORM stream: igtl:HOST:PORT[:STREAM], "
                                 "openhaptics[:NAME], forcedimension[:INDEX], emu:SOCKET, hid:..., polhem:..., null, "
                                 "playback:FILE (docs/devices.md)");
  sub->add_flag("--allow-unstable-stiffness", a->allow_unstable,
                "Run a stiffness above the stability bound at the force loop's rate (the TRANSFORM stream's, or a "
                "--haptic igtl: stream's, measured rate), as the scene's servo.allow_unstable_stiffness");
  auto* stream = sub->add_option("--stream", a->o.stream, "Device name of the TRANSFORMs that move the HIP (default StylusToTracker)");
  auto* offset = sub->add_option("--offset-mm", a->offset, "X,Y,Z added to the stream's translation [mm, RAS]")->expected(3)->delimiter(',');
  auto* registration = sub->add_option("--registration", a->registration,
                  "FILE: the tracker's rigid registration to the image, a 4x4 row by row (16 numbers, or 12 without "
                  "0 0 0 1; translation in mm, RAS): poses p -> R p + t, Force replies f -> R^T f; a TRANSFORM named "
                  "--registration-name from a client replaces it");
  sub->add_option("--registration-name", a->o.registration_name,
                  "Device name of a client's registration TRANSFORM (default TrackerToImage; \"\": none)");
  sub->add_option("--display-hz", a->o.display_hz, "HIP / proxy / force TRANSFORMs per second (default 60)")
      ->check(CLI::Range(1.0, 1000.0));
  auto* stale = sub->add_option("--stale-ms", a->stale_ms, "No TRANSFORM on the stream for this long: zero force (default 100)")
      ->check(CLI::Range(1.0, 10000.0));
  sub->add_option("--receive-timeout-ms", a->o.receive_timeout_ms,
                  "Longest silence inside a message before the client is dropped (default 2000)")
      ->check(CLI::Range(10, 600000));
  sub->add_option("--message-timeout-ms", a->o.message_timeout_ms,
                  "Longest a whole message may take from its first byte before the client is dropped (default 60000)")
      ->check(CLI::Range(10, 3600000));
  sub->add_option("--max-clients", a->o.max_clients,
                  "Clients connected at once (default 8); one more is answered with a STATUS and closed")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--idle-timeout-s", a->o.idle_timeout_s,
                  "A quiet client keeps its connection until the slots are full and a new one comes: then the "
                  "client that has sent no byte for longest, at least this long, is closed and the new one gets "
                  "its slot (default 60; 0: never); never a client that sent an IMAGE or a command")
      ->check(CLI::Range(0.0, 1e6));
  sub->add_option("--seconds", a->o.seconds, "Stop after this long (default: on SIGINT / SIGTERM only)")
      ->check(CLI::Range(0.0, 1e7));
  sub->add_flag("--journal,!--no-journal", a->o.journal,
                "Keep every edit of the session on the scene's volume in the edit journal, "
                "$XDG_STATE_HOME/isotouch/serve-CRC.journal (else ~/.local/state/isotouch; CRC: the volume's), written "
                "as applied and deleted when that session ends: a crash or kill loses no edit (default on)");
  sub->add_option("--restore", a->restore,
                  "A journal a killed serve left on this volume: yes (default) restores its edits, undo and redo "
                  "included, before the session starts (the log says \"restore N edits from HH:MM?\" and what was "
                  "done); no keeps it aside as JOURNAL.unrestored")
      ->check(CLI::IsMember({"yes", "no"}));
  sub->add_option("--save-dir", a->o.save_dir, "Folder the 'save NAME' command writes into (default: the current one)");
  sub->add_option("--image-hz", a->o.image_hz, "Edited-volume IMAGEs sent per second at most (default 2; 0: none)")
      ->check(CLI::Range(0.0, 100.0));
  sub->add_flag("--image-whole", a->o.image_whole,
                "Send the whole edited image, not the changed sub-volume (receivers that ignore sub-volumes)");
  auto* reply = sub->add_flag("--reply-force", a->o.reply_force,
                "Answer each TRANSFORM of --stream with a TRANSFORM 'Force' to its sender once the servo rendered it "
                "(lock-step, its header stamp echoed; never waited for)");
  sub->add_option("--memory-mib", a->o.memory_mib,
                  "Memory the server may use [MiB] (default: this machine's, its address-space and cgroup limits; "
                  "4096 where unknown): an IMAGE whose session, with every client's IMAGEs in flight, would pass "
                  "3/4 of it is refused with a STATUS")
      ->check(CLI::Range(1.0, 1e9));
  sub->add_flag("--realtime", a->o.sched_fifo, "Ask for SCHED_FIFO and pinning for the servo thread");
  haptic->excludes(stream)->excludes(offset)->excludes(stale)->excludes(reply)->excludes(registration);  // the stream's, not a device's
  return {sub, [a](const std::string& device) {
            service::ServeOptions o = a->o;
            if (a->offset.size() == 3) o.offset_mm = {a->offset[0], a->offset[1], a->offset[2]};
            if (!a->registration.empty()) o.registration = service::load_registration(a->registration);
            o.stale_s = a->stale_ms * 1e-3;
            o.restore = a->restore == "yes";
            o.run.device = device;
            o.run.progress = false;
            if (const char* f = std::getenv("ISOTOUCH_SERVE_TEST_FAULT")) o.fault_for_test = test_faults(f);
            io::Scene scene = io::load_scene(a->scene);
            scene.allow_unstable_stiffness = scene.allow_unstable_stiffness || a->allow_unstable;
            return service::serve(scene, o, std::cout);
          }};
}

}  // namespace isotouch::app
