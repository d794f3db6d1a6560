// isotouch-sculpt - a window where a person sculpts a volume and feels it (apps/sculpt/app.h).
#include <CLI/CLI.hpp>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>

#include "isotouch/apps/sculpt/app.h"
#include "isotouch/apps/cli_checks.h"
#include "isotouch/apps/cli_common.h"
#include "isotouch/apps/mesh_units_option.h"
#include "isotouch/apps/sculpt/scan_input.h"
#include "isotouch/session/stop_signal.h"

namespace isotouch::sculpt {
namespace {

/// A recording names the scene it replays, so --record takes a scene, not a volume: a usage
/// error (exit 2) that says how to get a scene for the volume.
void check_record_input(const Options& o) {
  if (o.record.empty() || is_scene_path(o.input)) return;
  const std::string dir = "out/" + std::filesystem::path(o.input).stem().string();
  throw CLI::ValidationError("--record", "needs a scene file (the recording names it), got the volume " + o.input +
                                             ": `isotouch run " + o.input + " --out " + dir + "` writes " + dir +
                                             "/scene.json for it; then `isotouch-sculpt " + dir +
                                             "/scene.json --record " + o.record + "`");
}

/// --size: W (a 4:3 window, height 3/4 of W) or WxH. Width 64 to 4096, height 48 (3/4 of 64)
/// to 4096 pixels, and at most
/// 4096 x 3072 pixels in all: 4-byte pixels within the 128 MiB storage binding every Vulkan
/// device offers (a larger framebuffer, a resized window, is drawn at a lower scale to fit).
void parse_size(const std::string& text, Options& o) {
  const auto bad = [&text](const std::string& why) {
    return CLI::ValidationError("--size", "must be W (height 3/4 of it) or WxH in pixels, width 64 to 4096, height 48 to "
                                          "4096, at most 4096x3072 pixels in all, got '" + text + "'" + (why.empty() ? "" : ": " + why));
  };
  if (text.empty()) throw bad("empty");
  const auto number = [&](const std::string& s) {
    if (s.empty() || s.size() > 5 || s.find_first_not_of("0123456789") != std::string::npos) throw bad("");
    return std::stoi(s);
  };
  const std::size_t x = text.find_first_of("xX");
  const int w = number(text.substr(0, x));
  const int h = x == std::string::npos ? w * 3 / 4 : number(text.substr(x + 1));
  if (w < 64 || w > 4096) throw bad("width " + std::to_string(w) + " outside 64 to 4096");
  if (h < 48 || h > 4096) throw bad("height " + std::to_string(h) + " outside 48 to 4096");
  if (std::int64_t(w) * h > std::int64_t(4096) * 3072)
    throw bad(std::to_string(std::int64_t(w) * h) + " pixels, more than 4096x3072 = 12582912");
  o.width = w;
  o.height = h;
}

}  // namespace
}  // namespace isotouch::sculpt

int main(int argc, char** argv) {
  isotouch::sculpt::Options o;
  CLI::App cli{
      "isotouch-sculpt: sculpt a volume and feel it. The mouse steers the probe (a simulated device coupled to "
      "the hand), the left button applies the tool while the probe touches the surface.\n"
      "Mouse: move = probe on the surface under the cursor, wheel = push deeper / pull back, Ctrl+wheel = zoom, "
      "right drag = orbit, middle drag = pan.\n"
      "Keys: 1 add, 2 carve, 3 smooth, 4 drill, [ ] radius, - = strength, Ctrl+Z undo, Ctrl+Y / Ctrl+Shift+Z redo, "
      "Ctrl+S save (.vdb, atomic), Ctrl+E export the isosurface (STL/OBJ/PLY), C clip plane, left press on a slice view moves the probe there, arrows orbit, PageUp/PageDown zoom, R reset camera, , and . roll the picture a quarter turn, H hide the overlay (probe glyphs and panels), Esc/Q quit.\n"
      "Exit status (docs/exit-codes.md): 0 ok; 1 bad input or error; 2 usage error; 3 Vulkan validation messages "
      "(--validation); 5 the haptic device was disconnected, faulty or sent refused reports; 6 a save or export "
      "failed; 130 / 143 stopped by SIGINT / SIGTERM.",
      "isotouch-sculpt"};
  isotouch::app::common_options(cli);
  cli.add_option("input", o.input, "a scene (.json, e.g. scenes/head.json), a volume file or a DICOM folder")->required();
  cli.add_option("--iso", o.iso,
                 "a volume's isovalue, in its units (HU for CT); with a scene, overrides the scene's. Without it a "
                 "volume opens at the isovalue its file stores (.vdb), at bone for CT in HU, else at the upper "
                 "threshold of a three-class Otsu on its histogram (the rule is printed)")
      ->check(isotouch::app::finite_number("the isovalue in the volume's units, e.g. --iso 300 for bone in HU"));
  cli.add_option("--inside", o.inside, "a volume's inside: above (CT) or below (signed distance)")
      ->check(CLI::IsMember({"above", "below"}));
  cli.add_option("--script", o.script, "input events to run (JSON; docs/user-guide.md, Input scripts)")->check(CLI::ExistingFile);
  cli.add_option("--screenshot", o.screenshot, "write the last frame as PNG; the script's screenshots go to its folder");
  cli.add_option("--window-shot", o.window_shot,
                 "write what the X server shows in the window at exit as PNG (the picture with the panels and slice "
                 "views, read back from the server)");
  cli.add_option("--present", o.present,
                 "how frames reach the screen: auto (X shared memory on a CPU device such as lavapipe with a local X "
                 "server offering MIT-SHM, else the Vulkan swapchain), shm (fails where it cannot be set up) or swapchain")
      ->check(CLI::IsMember({"auto", "shm", "swapchain"}));
  cli.add_option("--frames", o.frames, "stop after N frames (0: until the window is closed)")->check(CLI::NonNegativeNumber);
  cli.add_option("--record", o.record,
                 "record the session (ticks and edits) for isotouch replay; the input must be a scene (.json): "
                 "`isotouch run VOLUME --out DIR` writes DIR/scene.json for a volume");
  cli.add_flag("--journal,!--no-journal", o.journal,
               "keep every applied edit in the edit journal, $XDG_STATE_HOME/isotouch/sculpt-CRC.journal (else "
               "~/.local/state/isotouch; CRC: the volume's), each edit written as applied (fdatasync'ed every 0.25 s) "
               "and the file deleted at a clean exit: a crash or kill loses no edit (default on)");
  cli.add_option("--restore", o.restore,
                 "a journal left by a session that did not end cleanly on the same volume: yes restores its edits "
                 "(undo and redo included) before the session starts, no does not, ask (default) asks \"restore N "
                 "edits from HH:MM?\" on the terminal (none: not restored); one not restored is kept as "
                 "JOURNAL.unrestored")
      ->check(CLI::IsMember({"yes", "no", "ask"}));
  cli.add_option("--save", o.save_path, "where Ctrl+S saves, in the format the name asks for: .vdb, or .nrrd, .mha, .nii, .nii.gz "
                 "(3D Slicer; default INPUT-sculpted.vdb in the working folder)");
  cli.add_option("--export", o.export_path, "where Ctrl+E writes the isosurface mesh (.stl, .obj, .ply; default INPUT-sculpted.stl)");
  isotouch::app::add_mesh_units_option(cli, o.mesh_units);
  std::string size;
  CLI::Option* size_opt = cli.add_option("--size", size,
                 "the window's size in pixels: W (height 3/4 of it; default 1024) or WxH (e.g. 1920x1080); width 64 to "
                 "4096, height 48 to 4096, at most 4096x3072 pixels in all");
  cli.add_option("--render-scale", o.render_scale, "draw at this fraction of the window's resolution (faster on a CPU device)")
      ->check(CLI::Range(0.1, 1.0));
  cli.add_option("--frame-budget-ms", o.frame_budget_ms,
                 "while the view moves, draw at the resolution that keeps a frame within this many ms (upscaled; "
                 "full resolution when it stops; 0: always --render-scale)")
      ->check(CLI::Range(0.0, 1000.0));
  cli.add_option("--edit-wait-ms", o.edit_wait_ms,
                 "a frame waits at most this long for the brush it submitted, so that it shows it (0: never)")
      ->check(CLI::Range(0.0, 1000.0));
  cli.add_flag("--bench", o.bench,
               "run a scripted sculpt (probe onto the surface, a carve stroke, undo; or --script) and print frame "
               "time, edit-to-pixels and servo figures with verdicts against the targets (frames drawn whole: median 33, "
               "p95 50 ms; servo misses while sculpting <= alone + 3 sqrt(alone))");
  cli.add_option("--bench-ticks", o.bench_ticks,
                 "with --bench: repeat its sculpt rounds until the servo has ticked this many times, then run the "
                 "servo alone as long (the servo verdict needs >= 20000 each; 0: no servo-alone phase)")
      ->check(CLI::Range(0L, 10000000L));
  cli.add_flag("--point-probe", o.point_probe,
               "feel every tool as a point (for comparison); by default a carve or drill brush of radius r is felt "
               "as a sphere of radius r (what touches is what cuts; the brush cuts to its surface and at most half "
               "a voxel beyond), and [ ] change both");
  cli.add_flag("--stats", o.stats, "print frame time, edit-to-pixels latency and servo figures at exit");
  cli.add_flag("--sim-clock", o.sim_clock,
               "run the servo and the edits on a simulated clock, one frame's worth of ticks per frame, on the "
               "window's thread: a script then gives the same recording and screenshots every run (the window's own "
               "mouse and keys are ignored; the mouse probe only; the stats panel shows the simulated frame time)");
  cli.add_option("--sim-frame-ms", o.sim_frame_ms, "simulated time per frame with --sim-clock [ms] (whole servo ticks)")
      ->check(CLI::Range(0.1, 1000.0));
  cli.add_flag("--validation", o.validation, "enable the Vulkan validation layer (exit 3 on any message)");
  cli.add_flag("--sched-fifo,!--no-sched-fifo", o.sched_fifo,
               "SCHED_FIFO, CPU pinning and locked memory for the servo thread (default on; refused: a note)");
  cli.add_flag("--display-off-servo-cpu,!--no-display-off-servo-cpu", o.display_off_servo_cpu,
               "keep the local X server off the servo thread's CPU while the window is open, and present from "
               "another CPU: a software-presented frame goes through the X socket in system calls that hold a CPU "
               "for milliseconds (default on, with a pinned servo; refused: a note). This changes the CPU sets "
               "(sched_setaffinity) of the X server's threads, outside this process: they are given back at exit, "
               "on a signal, and, if this process is killed or crashes, by a guard process it starts (named in the "
               "log); a thread the server started meanwhile keeps the reduced set until the server restarts");
  cli.add_flag("--overlay,!--no-overlay", o.overlay,
               "the tool and stats panels (Dear ImGui) over the picture (default on, in a build with Dear ImGui)");
  cli.add_flag("--slices,!--no-slices", o.slices,
               "the slice views: axial, coronal and sagittal planes through the probe (HIP) at the window's right "
               "edge, with a window/level, the isocontour and the HIP (yellow) and proxy (green) marks; a press on one "
               "moves the mouse probe's target there (default on; in the screenshots too; H hides them)");
  cli.add_option("--slices-png", o.slices_png,
                 "write the three slices (one pixel per voxel) and slices.json into DIR at exit, and into DIR/NAME/ "
                 "with each script screenshot NAME.png");
  cli.add_flag("--tile-starts,!--no-tile-starts", o.tile_starts,
               "start each pixel's march where its 8x8 tile's rays can first meet the surface (default on; off "
               "draws the same picture, slower: to measure what they save)");
  cli.add_option("--device", o.device, "Vulkan device: name substring or index");
  cli.add_option("--haptic", o.haptic,
                 "the haptic device: mouse (default: a simulated device coupled to the hand the mouse steers), "
                 "null, playback:FILE (trace.csv or .rec), hid:VID:PID[:SERIAL], hid:/dev/hidrawN, polhem:..., emu:SOCKET "
                 "(isotouch-devemu), openhaptics[:NAME], forcedimension[:INDEX], igtl:HOST:PORT[:STREAM] (a PlusServer's "
                 "stylus; docs/devices.md); a device's caps must fit the scene's stiffness, damping and force limit");
  cli.add_flag("--allow-unstable-stiffness", o.allow_unstable_stiffness,
               "run a stiffness above the stability bound (for --haptic igtl:, the one at the stream's measured rate), "
               "as the scene's servo.allow_unstable_stiffness");
  cli.parse_complete_callback([&o, &size, size_opt] {
    // Given at all, parsed: CLI11 takes `--size ""` as an empty value, not as no option.
    if (size_opt->count() > 0) isotouch::sculpt::parse_size(size, o);
    isotouch::sculpt::check_record_input(o);
  });
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return isotouch::app::parse_exit(cli, e);
  }
  int rc = isotouch::exit_code::kError;
  // SIGINT / SIGTERM / SIGHUP / SIGQUIT end the frame loop, so that the session stops, the recording is
  // completed and the X server gets its CPUs back (exit 128 + the signal).
  isotouch::session::install_stop_handlers();
  try {
    // A file dropped on the window that can be read opens in a new session.
    for (;;) {
      std::optional<isotouch::sculpt::Options> next;
      rc = isotouch::sculpt::run_sculpt(o, std::cerr, &next);
      if (const int sig = isotouch::session::stop_signal(); sig != 0) {
        std::cerr << "sculpt   stopped by signal " << sig << "\n";
        rc = isotouch::exit_code::signalled(sig);
        break;
      }
      if (rc != 0 || !next) break;
      o = *next;
    }
  } catch (const std::exception& e) {
    std::cerr << "isotouch-sculpt: " << e.what() << "\n";
    rc = isotouch::exit_code::kError;
  }
  // A dropped file still loading (a reader blocked on its file system): everything is written
  // and closed; exit without waiting for it or running static destructors under it.
  if (isotouch::sculpt::loads_running() > 0) {
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
    std::_Exit(rc);
  }
  return rc;
}
