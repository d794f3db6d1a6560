// shapes.h - the paper's synthetic scenes with their exact geometry (the truth).
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "script.h"
#include "volume.h"

namespace isotouch::engine {

/// A solid with known geometry, in world [m].
class Shape {
 public:
  virtual ~Shape() = default;
  /// Closest point on the surface to x and the outward unit normal there.
  virtual void closest(const servo::Vec3& x, servo::Vec3& point, servo::Vec3& normal) const = 0;
  /// Signed distance to the surface, positive inside [m].
  virtual double depth(const servo::Vec3& x) const = 0;
};

/// A synthetic scene: the sampled volume, the shape it samples, and a default stroke.
struct SyntheticScene {
  std::string name;
  Volume volume;
  std::unique_ptr<Shape> truth;
  double tau = 0;                      ///< isovalue; inside is value > tau
  servo::ScriptParams script;          ///< a stroke that stays on the surface
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
///   C(t) = ((R + r cos 3t) cos 2t, (R + r cos 3t) sin 2t, r sin 3t), R = 16, r = 7
///   voxels, around the grid centre; value = (3.5 mm - distance to C) in mm, tau = 0.
///   Strands stay 14 voxels apart; the distance to C is found by sampling C at 512
///   points and refining with Newton steps on t (to 1e-9 m).
/// @throws VolumeError for an unknown name.
SyntheticScene make_synthetic_scene(const std::string& name);

}  // namespace isotouch::engine
