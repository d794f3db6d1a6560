// run_cmd.cpp - `isotouch run`. See run_cmd.h.
#include "isotouch/apps/run_cmd.h"

#include <cctype>
#include <filesystem>
#include <fstream>
#include <optional>
#include <iomanip>
#include <iostream>
#include <memory>
#include <string>

#include "isotouch/core/exit_codes.h"
#include "isotouch/run/live_run.h"
#include "isotouch/apps/run_job.h"
#include "isotouch/apps/cli_checks.h"
#include "isotouch/apps/mesh_units_option.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/files.h"
#include "isotouch/run/stroke_warning.h"
#include "isotouch/run/volume_scene.h"
#include "isotouch/sim/sim_device.h"
#include "isotouch/session/stop_signal.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace isotouch::app {
namespace fs = std::filesystem;
namespace {

// `isotouch run --help` footer: the scene format in short (docs/user-guide.md, "Scenes", gives every field).
constexpr const char* kSceneHelp = R"(
Scene file (JSON; unknown or repeated keys are errors; units are in the key names):
  {
    "name": "head",                             letters, digits, '-', '_' (default: file stem)
    "volume": {"path": "../data/ct-head-headsq/headsq_64x64x93_int16.mhd"},
                                                relative to the scene file; .mhd .mha .nrrd .nhdr .nii .nii.gz
                                                .vdb, or a DICOM series folder (one file per slice)
           or {"synthetic": "sphere", "dims": [64, 64, 64], "spacing_m": 0.001, "radius_vox": 20}
           or {"synthetic": "box" | "three-spheres" | "knot"}
    "isovalue": 1150,                           required; in the volume's units (HU for CT)
    "inside": "above",                          "above": value > isovalue is inside; "below"
    "servo":  {"stiffness_n_per_m": 800, "damping_n_s_per_m": 1.0, "plane_update_period": 5,
               "rate_hz": 1000, "force_limit_n": 3.3, "variant": "robust" | "paper", ...},
                                                optional, like every section below; see docs/user-guide.md, Scenes.
                                                A stiffness above the stability bound 2 (b - |B|) / T
                                                (b: device + hand damping) is refused unless
                                                "allow_unstable_stiffness": true
    "device": {"mass_kg": 0.08, "hand_stiffness_n_per_m": 300, "hand_damping_n_s_per_m": 5,
               "workspace_scale": 1, ...}          world m per device m, in [0.0001, 10]
    "script": {"ray_origin_frac": [0.5, 0.5, 1.2], "ray_direction": [0, 0, -1],
               "stroke_direction": [1, 0, 0], "press_depth_m": 0.008, "stroke_length_m": 0.04, ...},
    "outputs": {"trace_csv": true, "plots": true},
    "engine": {"passes": [{"gaussian": {"sigma_mm": 1.0}}, {"closing": {"radius_mm": 1}}, "gradient"],
               "mode": "sparse" | "dense", "samples": "fp32" | "fp16" | "unorm16"},
    "edits": {"brush": {"kind": "drill", "radius_mm": 4.5, "falloff": 0.5, "force_threshold_n": 0.5,
                        "removal_per_n_s": 2, ...},  also strength, density_scale, material, empty
              "every_ticks": 10, "button": [[0.5, 4.6]], "history_limit_mib": 64,
              "write_vdb": true, "write_stl": true,
              "timeline": [{"t_s": 1.0, "kind": "carve", "at": "vhip" | [x, y, z] (mm), "duration_s": 0.2,
                            "radius_mm": 3, ...}, {"t_s": 2.0, "kind": "undo" | "redo"}]}
  }
edits (optional, needs mode "sparse"): sculpting while the servo runs. While the
button is down and the probe is in contact, the brush is applied at the VHIP every
every_ticks ticks (drill: removal grows with |F| above force_threshold_n; removal_per_n_s is
the fraction of the material-to-empty value range removed per N above it per s, the same on
every volume; "rate" gives it in value units per N s instead), one undo stroke
per press; timeline brushes fire at their time. Each edit recomputes only the bricks it can
change and publishes a new snapshot the next tick reads. Outputs add edits.csv, edits.png
(force, depth and removed volume against time), before.png / after.png, drilled.vdb and
drilled.stl. Shipped: scenes/drill-skull.json.
engine (optional): the passes that compute the published samples, in order; a pass is its
name or {"name": {parameters}}: gaussian (sigma_mm > 0), closing (radius_mm >= 0, a box),
gradient (required, after the filters), brick_minmax (halo 0..8, default 1). Only the listed
passes' pipelines and buffers are created; report.md and summary.json list what ran and what
was left out. Default: ["gradient"], mode "sparse" (only 8^3 bricks near the isosurface are
computed and published), samples "fp32" (16 B per sample; fp16 and unorm16 are 8 B and need
mode "sparse"). mode "dense" computes every voxel, for comparison.
The script casts a ray from ray_origin_frac (fractions of the volume box, each in [-2, 3])
to the first isosurface crossing, presses the hand target press_depth_m in, strokes
stroke_length_m along the surface, and lifts off. Shipped: scenes/head.json, chest.json,
chest-full.json (the chest's DICOM series at full resolution), sphere.json, knot.json,
drill-skull.json. `run --record FILE` also writes a recording that
`isotouch replay FILE` plays back, checking every force bit for bit.

Outputs in --out: trace.csv (one row per tick), summary.json, report.md, plots (gnuplot).
Points are reported in the volume's physical frame (origin + direction x spacing x index).
Exit status (docs/exit-codes.md): 0 ok; 1 bad input (the message names the file, field and
value); 2 usage error (an unknown option, a bad value); 4 the run had servo fault ticks;
5 (--live) the haptic device was disconnected, faulty or sent refused reports; 130 / 143
stopped by SIGINT / SIGTERM (summary.json says "interrupted"; a second signal stops at once,
summary.json still says "interrupted").

The Vulkan device: --device NAME|INDEX, before or after `run`, or ISOTOUCH_DEVICE.

Example:
  isotouch run scenes/sphere.json --out /tmp/sphere --device llvmpipe
)";

std::string default_scene() {
  if (fs::exists("scenes/head.json")) return "scenes/head.json";
  return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "head.json").string();
}

/// What `run` was given besides its options: a scene file, or a volume with its --iso.
struct RunInput {
  std::string path;
  std::optional<double> iso;
  std::string inside = "above";
};

/// True when `path` is a file whose first non-blank byte is '{' (a scene with another name).
bool looks_like_json(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char c = 0;
  while (in.get(c))
    if (!std::isspace(static_cast<unsigned char>(c))) return c == '{';
  return false;
}

/// The scene to run: the scene file, or the default scene made for a volume (said on `out`
/// and written as OUT_DIR/scene.json when `out_dir` is given: "" keeps it unwritten).
/// @throws io::SceneError for a file that is neither, or --iso with a scene.
io::Scene run_input_scene(const RunInput& in, std::string* out_dir, std::ostream& out) {
  std::error_code ec;
  const bool volume = run::is_volume_path(in.path);
  if (!volume && in.iso) throw io::SceneError(in.path + ": --iso is for a volume; a scene gives its own isovalue");
  if (!volume) {
    if (fs::path(in.path).extension() != ".json" && fs::is_regular_file(in.path, ec) && !looks_like_json(in.path))
      throw io::SceneError(in.path + ": neither a scene (JSON) nor a volume (.mhd .mha .nrrd .nhdr .nii .nii.gz "
                                     ".vdb, or a DICOM series folder)");
    return io::load_scene(in.path);
  }
  run::VolumeScene vs = run::make_volume_scene(in.path, in.iso, in.inside);
  out << "isotouch run: volume " << in.path << ": a default touch scene\n"
      << "scene    " << engine::iso_line(vs.choice) << "\n"
      << "scene    the probe approaches " << vs.approach_text << "\n";
  if (out_dir) {
    if (out_dir->empty()) *out_dir = (fs::path("out") / vs.scene.name).string();
    const std::string file = (fs::path(*out_dir) / "scene.json").string();
    io::write_file_atomic(file, vs.json);
    out << "scene    written to " << file << " (edit it and run it: isotouch run " << file << ")\n";
  }
  return std::move(vs.scene);
}

int cmd_run_live(const RunInput& in, std::string out_dir, const std::string& device, bool quiet,
                 const std::string& record_path, const std::string& haptic, bool allow_unstable) {
  io::Scene scene = run_input_scene(in, out_dir.empty() ? nullptr : &out_dir, std::cout);
  scene.allow_unstable_stiffness = scene.allow_unstable_stiffness || allow_unstable;
  const std::string& scene_path = in.path;
  LiveOptions opt;
  opt.haptic = haptic;
  opt.run.out_dir = out_dir;
  opt.run.device = device;
  opt.run.progress = !quiet;
  opt.run.record_path = record_path;
  std::cout << "isotouch run --live: scene " << scene_path << "\n";
  return run_live(scene, opt, std::cout);
}

int cmd_run(const RunInput& in, std::string out_dir, const std::string& device, bool quiet,
            const std::string& record_path, io::MeshUnits mesh_units) {
  const io::Scene scene = run_input_scene(in, &out_dir, std::cout);
  const std::string& scene_path = in.path;
  if (out_dir.empty()) out_dir = (fs::path("out") / scene.name).string();
  RunOptions opt;
  opt.out_dir = out_dir;
  opt.device = device;
  opt.progress = !quiet;
  opt.record_path = record_path;
  opt.mesh_units = mesh_units;
  std::cout << "isotouch run: scene " << scene_path << " -> " << out_dir << "/\n";
  {
    const double dt = 1.0 / scene.hri.rate_hz;
    const int need = sim::min_stable_substeps(scene.device, dt);
    if (need > scene.device.substeps)
      std::cout << "device   substeps raised from " << scene.device.substeps << " to " << need
                << " per servo period so the simulated device integrates stably (mass " << scene.device.mass_kg
                << " kg, hand " << scene.device.hand_stiffness_n_per_m << " N/m and "
                << scene.device.hand_damping_n_s_per_m << " N s/m)\n";
  }
  session::install_stop_handlers();  // SIGINT/SIGTERM: stop at the next safe point, folder marked
  RunMetrics m;
  try {
    m = run_scene(scene, opt, std::cout);
  } catch (const session::Interrupted& e) {
    std::cerr << "\nisotouch run: " << e.what() << "; " << (fs::path(out_dir) / "summary.json").string()
              << " says \"status\": \"interrupted\" and lists the files that were finished\n";
    return exit_code::signalled(e.signal);
  }
  const auto& hp = scene.hri;
  const double limit = hp.force_limit_n;
  std::cout << std::setprecision(4)
            << "\n== isotouch summary: " << scene.name << " ==\n"
            << "  volume        " << m.volume_path << "  (" << m.dims[0] << "x" << m.dims[1] << "x" << m.dims[2]
            << (m.orientation.empty() ? std::string() : ", orientation " + m.orientation) << ")\n"
            << "  isovalue      " << hp.tau << "\n"
            << (m.cpu_backend ? "  engine        " : "  GPU           ") << m.gpu_device << ": gradient "
            << m.gpu_gradient_ms << " ms; CPU reference " << m.cpu_gradient_ms << " ms\n"
            << (m.cpu_backend ? "  vs reference  max abs " : "  GPU vs CPU    max abs ") << m.max_abs_diff
            << ", relative " << m.max_rel_diff << "\n"
            << "  servo         HRI, n = " << hp.plane_update_period << ", " << hp.rate_hz << " Hz, K = "
            << hp.stiffness_n_per_m << " N/m, B = " << hp.damping_n_s_per_m << " N s/m\n"
            << "  ticks         " << m.ticks << "  (tick median " << m.tick_ns_median << " ns, p99 " << m.tick_ns_p99
            << " ns, max " << m.tick_ns_max << " ns)\n"
            << "  contact       " << m.contact_ticks << " ticks, max force " << m.max_force_n << " N (limit "
            << limit << " N), max penetration " << m.max_penetration_m * 1e3 << " mm\n"
            << "  force step    max " << m.max_force_step_n << " N between two contact ticks ("
            << (limit > 0 ? 100.0 * m.max_force_step_n / limit : 0.0) << " % of the limit, at t = "
            << m.max_force_step_t_s << " s)\n"
            << "  faults        " << m.fault_ticks << " of " << m.ticks << " ticks\n"
            << "  surface error RMS " << m.surface_err_rms_m * 1e3 << " mm, max " << m.surface_err_max_m * 1e3 << " mm\n"
            << "  report        " << (fs::path(out_dir) / "report.md").string()
            << (m.plots_drawn ? "  (with plots)" : ("  (" + m.plot_note + ")")) << "\n";
  if (const std::string w = run::stroke_contact_warning(m); !w.empty()) std::cerr << "\nisotouch: warning: " << w << "\n";
  if (m.fault_ticks > 0) {
    std::cerr << "\nisotouch: error: " << m.fault_ticks << " of " << m.ticks
              << " servo ticks were faults (non-finite input or state; zero force sent): the run is not "
                 "trustworthy. See "
              << (fs::path(out_dir) / "trace.csv").string() << " (column fault).\n";
    return exit_code::kServoFaults;
  }
  return exit_code::kOk;
}

}  // namespace

Subcommand add_run_command(CLI::App& cli) {
  struct Args {
    RunInput in;
    std::string out_dir, record_path, haptic = "sim", hand_path;
    bool quiet = false, live = false, allow_unstable = false;
    io::MeshUnits mesh_units = io::MeshUnits::kMillimetre;
  };
  auto a = std::make_shared<Args>();
  auto* run = cli.add_subcommand("run", "Simulate a probe touching and stroking the isosurface of a scene; "
                                        "write trace.csv, summary.json, report.md and plots");
  a->in.path = default_scene();
  run->add_option("scene", a->in.path,
                  "Scene JSON file, or a volume file or DICOM folder: a default touch scene is made for it "
                  "(written as OUT/scene.json)")
      ->capture_default_str();
  run->add_option("--iso", a->in.iso, "With a volume: its isovalue (default: the one its file and histogram choose)")
      ->check(finite_number("the isovalue in the volume's units, e.g. --iso 300 for bone in HU"));
  run->add_option("--inside", a->in.inside, "With --iso: above (CT density) or below (signed distance)")
      ->check(CLI::IsMember({"above", "below"}));
  run->add_option("--out,-o", a->out_dir,
                  "Output folder (default: out/<scene name>; with --live: none unless given, then trace.csv of the "
                  "renderer's ticks, report.md and summary.json)");
  run->add_flag("--quiet,-q", a->quiet, "No progress line");
  run->add_option("--record", a->record_path,
                  "Also write every device input, button and edit with its time to FILE (replay it with "
                  "`isotouch replay FILE`)");
  run->add_flag("--live", a->live,
                "Run the scene in real time on the live session's threads: the servo thread (SCHED_FIFO when "
                "allowed) drives the simulated device, an edit thread applies the button drill and the timeline; "
                "with --record FILE the recording is streamed while it runs (FILE.part until it stops; a killed "
                "run leaves FILE.part, replayable up to its last chunk)");
  run->add_option("--haptic", a->haptic,
                  "With --live: the haptic device, KIND[:ARGS]: sim (the scene's simulated device, default), null, "
                  "playback:FILE (trace.csv or .rec), hid:VID:PID[:SERIAL], hid:/dev/hidrawN, emu:SOCKET "
                  "(isotouch-devemu), igtl:HOST:PORT[:STREAM] (an OpenIGTLink source such as a PlusServer: the "
                  "stream's TRANSFORM is the device, the force goes back as a TRANSFORM 'Force'); `isotouch devices` "
                  "lists the HID devices")
      ->capture_default_str();
  run->add_flag("--allow-unstable-stiffness", a->allow_unstable,
                "With --live: run a stiffness above the Colgate-Schenkel bound of the device's loop (an igtl "
                "stream's measured rate), as the scene's servo.allow_unstable_stiffness");
  run->add_option("--hand-path", a->hand_path,
                  "Write the scene's scripted hand (device frame, t_s,x_m,y_m,z_m every ms) to FILE for "
                  "isotouch-devemu --path, and exit");
  add_mesh_units_option(*run, a->mesh_units)->description(
      "Unit of drilled.stl's coordinates (a scene with edits; physical frame, LPS): mm (default, what 3D Slicer and "
      "3D-printing slicers read) or m");
  run->footer(kSceneHelp);
  run->parse_complete_callback([a, run] {
    if (!a->live && run->count("--haptic") > 0)
      throw CLI::ValidationError("--haptic needs --live (a simulated run drives the scene's simulated device)");
    if (a->live && run->count("--mesh-units") > 0)
      throw CLI::ValidationError("--mesh-units is for drilled.stl, which a simulated run writes, not --live");
  });
  return {run, [a](const std::string& device) {
            if (!a->hand_path.empty())
              return write_hand_path(run_input_scene(a->in, nullptr, std::cout), a->hand_path, std::cout);
            if (a->live) return cmd_run_live(a->in, a->out_dir, device, a->quiet, a->record_path, a->haptic, a->allow_unstable);
            return cmd_run(a->in, a->out_dir, device, a->quiet, a->record_path, a->mesh_units);
          }};
}

}  // namespace isotouch::app
