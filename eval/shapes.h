// shapes.h - the paper's synthetic scenes with their exact geometry (the truth).
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "isotouch/sim/script.h"
#include "isotouch/engine/volume.h"

namespace isotouch::eval {

/// A solid with known geometry, in world [m].
class Shape {
 public:
  virtual ~Shape() = default;
  /// Closest point on the surface to x and the outward unit normal there.
  virtual void closest(const core::Vec3& x, core::Vec3& point, core::Vec3& normal) const = 0;
  /// Signed distance to the surface, positive inside [m].
  virtual double depth(const core::Vec3& x) const = 0;
};

/// A synthetic scene: the sampled volume, the shape it samples, and a default stroke.
struct SyntheticScene {
  std::string name;
  engine::Volume volume;
  std::unique_ptr<Shape> truth;
  double tau = 0;                      ///< isovalue; inside is value > tau
  sim::ScriptParams script;          ///< a stroke that stays on the surface
  /// Optional prescribed HIP path, world [m], one point per tick at 1 kHz: sweeps replay
  /// it instead of recording the script on the simulated device (the knot uses it to
  /// slide exactly along its concave side).
  std::vector<core::Vec3> hip_path;
  std::size_t slide_begin = 0, slide_end = 0;  ///< ticks of hip_path that slide on the surface
  std::string description;
};

/// Names accepted by make_synthetic_scene.
std::vector<std::string> synthetic_scene_names();

/// Build one of the paper's synthetic scenes on a 64^3 grid of 1 mm voxels:
/// - "sphere": radius 20 voxels, the value is the signed distance in mm (tau = 0);
/// - "box": 32 x 24 x 18 voxels, centre off the grid by a fraction of a voxel, signed
///   distance in mm (tau = 0);
/// - "three-spheres": three spheres of radius 9 voxels and densities 150, 300 and 600
///   with a linear edge ramp 4 voxels wide, value = max of the three, tau = 100: each
///   isosurface is a sphere of radius 9 + 4 (1/2 - tau / density) voxels;
/// - "knot": a tube of radius 3.5 voxels around the (2,3) torus knot (trefoil)
///   C(t) = ((R + r cos 3t) cos 2t, (R + r cos 3t) sin 2t, r sin 3t), R = 14, r = 8
///   voxels, around the grid centre; value = (3.5 mm - distance to C) in mm, tau = 0.
///   Strands stay 10.2 voxels apart (a 3.2-voxel gap); the distance to C is found by
///   sampling C at 512 points and refining with Newton steps on t (to 1e-9 m). At
///   t = pi the centre line bends with a radius of 15 voxels, so the side of the tube
///   facing its centre of curvature is concave along the tube (radius 11.5 voxels). The
///   hip_path approaches that side from 2 mm outside, then slides 0.5 mm deep along the
///   tube (t in [pi - 0.2, pi + 0.2], 10.7 mm in 0.25 s) on a rotation-minimizing frame.
/// @throws VolumeError for an unknown name.
SyntheticScene make_synthetic_scene(const std::string& name);

}  // namespace isotouch::eval
