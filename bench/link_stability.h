// link_stability.h - `isotouch stability`'s link sweep: the largest stable K of a wall
// pressed through a delayed link (sim/linked_contact.h) against the round-trip delay and
// the link rate, without and with the time-domain passivity controller at the device end,
// and what the controller costs in transparency at K = 800 N/m.
#pragma once
#include <iosfwd>
#include <string>

namespace isotouch::bench {

/// Round trips 0, 1, 2, 5, 10, 20 ms x link rates 100, 250, 500, 1000 Hz: K_max without
/// and with the controller (log bisection over 10-1e5 N/m), whether K = 800 N/m is stable
/// either way, and the slow press's force at K = 800 with the controller against the
/// undelayed 1 kHz run's. Writes DIR/link_stability.csv and DIR/link_stability.md;
/// prints one progress line per cell. `quick`: shorter runs, coarser search.
/// @return 0, or 4 if K = 800 with the controller is unstable in some cell.
int run_link_stability(const std::string& out_dir, bool quick, std::ostream& log);

/// The same sweep on a scan: presses on the isosurface of `scene_path`'s volume (its
/// isovalue and inside) where the scene's script ray first meets it, along the outward
/// normal there, through the same link and device; DIR/link_stability_scene.csv and .md.
/// @throws io::SceneError, engine::VolumeError naming the file; std::runtime_error when the
///         scene's volume is synthetic or its ray never meets the isosurface.
/// @return as run_link_stability.
int run_link_stability_on_scene(const std::string& scene_path, const std::string& out_dir, bool quick,
                                std::ostream& log);

}  // namespace isotouch::bench
