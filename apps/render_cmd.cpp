// render_cmd.cpp - `isotouch render`: options only; the rendering is run/render_job.h.
#include "isotouch/apps/render_cmd.h"

#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

#include "isotouch/apps/cli_checks.h"
#include "isotouch/run/render_job.h"

#ifndef ISOTOUCH_SOURCE_DIR
#define ISOTOUCH_SOURCE_DIR "."
#endif

namespace isotouch::app {
namespace fs = std::filesystem;
namespace {

std::string default_scene_path() {
  if (fs::exists("scenes/head.json")) return "scenes/head.json";
  return (fs::path(ISOTOUCH_SOURCE_DIR) / "scenes" / "head.json").string();
}

}  // namespace

Subcommand add_render_command(CLI::App& cli) {
  auto o = std::make_shared<run::RenderOptions>();
  Subcommand s;
  s.app = cli.add_subcommand(
      "render",
      "Ray-cast the scene's isosurface to a PNG (headless, any Vulkan device).\n"
      "The surface is the trilinear field the servo feels, at the scene's isovalue. Camera: an orbit\n"
      "around the object's centre (--frame-scan: the scan's); angles in the volume's physical frame (LPS for medical images):\n"
      "azimuth 0 looks at the face from the front (eye anterior), 90 from the patient's left, -90\n"
      "from the right, 180 from behind; elevation > 0 looks down from above; physical +z is up.\n"
      "With --time T the probe at that time of the scene's run is drawn in: HIP (yellow, seen\n"
      "through the surface), VHIP (green), the virtual plane (translucent cyan disc), the force\n"
      "(red arrow); the scene is run first unless --trace gives its trace.csv.\n"
      "Example: isotouch render scenes/head.json --out head.png --azimuth -90 --time 1.2");
  s.app->add_option("scene", o->scene, "Scene file (default scenes/head.json)");
  s.app->add_option("--out", o->out, "PNG file to write (default <scene name>.png)");
  s.app->add_option("--width", o->width, "Image width [pixels]; width x height at most the device's storage-binding limit / 4 B (lavapipe: 128 MiB, 33554432 pixels)")->capture_default_str()->check(CLI::Range(1, 8192));
  s.app->add_option("--height", o->height, "Image height [pixels]; see --width")->capture_default_str()->check(CLI::Range(1, 8192));
  s.app->add_option("--azimuth", o->cam.azimuth_deg, "Camera azimuth about physical +z [deg]")
      ->capture_default_str()
      ->check(CLI::Range(-3600.0, 3600.0));  // also refuses nan / inf
  s.app->add_option("--elevation", o->cam.elevation_deg, "Camera elevation [deg], in (-90, 90)")
      ->capture_default_str()
      ->check(CLI::Range(-89.9, 89.9));
  s.app->add_option("--zoom", o->cam.zoom, "Zoom: 1 fits the object (its isosurface's box, stray voxels left out), 2 is twice as close")
      ->capture_default_str()
      ->check(positive_number());
  s.app->add_option("--distance", o->cam.distance_m, "Eye to the object's centre [m] before zoom (0: fit the object)")
      ->capture_default_str()
      ->check(non_negative_number());
  s.app->add_flag("--frame-scan", o->frame_scan,
                  "Aim at the scan's box instead of the object's (one camera for volumes on one grid)");
  s.app->add_option("--fov", o->cam.fov_y_deg, "Vertical field of view [deg]")->capture_default_str()->check(CLI::Range(1.0, 120.0));
  s.app->add_option("--up", o->up, "Physical axis shown up: x, -x, y, -y, z, -z (default z: superior for a medical "
                    "image, whose direction matrix says where that is)");
  s.app->add_option("--front", o->front, "Physical axis the eye is on at azimuth 0 (default -y: anterior)");
  s.app->add_option("--time", o->time_s, "Draw the probe at this time of the scene's run [s]")->check(non_negative_number());
  s.app->add_option("--trace", o->trace, "With --time: the run's trace.csv (default: run the scene now)")
      ->check(CLI::ExistingFile);
  s.app->add_option("--clip", o->clip_axis,
                    "Cut away the half of the volume toward this physical axis: x, -x, y, -y, z, -z "
                    "(e.g. -y removes the anterior half)");
  s.app->add_option("--clip-at", o->clip_at, "Where the clip plane lies along that axis, 0..1 of the volume")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  s.app->add_option("--step", o->step, "March step along the ray [voxels]; at most 0.9 (the hit is refined within one step from the 3x3x3 voxels around it)")->capture_default_str()->check(CLI::Range(0.02, 0.9));  // ISOTOUCH_RAYCAST_MAX_STEP (make_params compares in float)
  s.app->add_flag("--path", o->path,
                  "Draw the run report's picture instead: the surface around the contact, the HIP's path, the "
                  "contact points coloured by force (the scene is run unless --trace is given)");
  s.app->add_flag("--no-skip", o->no_skip, "Turn empty-space skipping off (same picture, slower)");
  s.app->add_flag("--cpu", o->cpu, "Use the CPU reference ray caster instead of Vulkan");
  s.run = [o](const std::string& device) {
    run::RenderOptions c = *o;
    if (c.scene.empty()) c.scene = default_scene_path();
    if (!c.trace.empty() && !c.time_s && !c.path) throw std::runtime_error("render: --trace needs --time or --path");
    return run::run_render(c, device);
  };
  return s;
}

}  // namespace isotouch::app
