// baselines.h - the two methods the HRI paper compares against (its Table 1), under the
// same Renderer interface and the same force conventions as HriRenderer.
#pragma once
#include "isotouch/servo/core_names.h"
#include "isotouch/servo/renderer.h"

namespace isotouch::servo {

/// Parameters shared by the baselines (device space for K and B, as in HriParams).
struct BaselineParams {
  double tau = 0.0;                   ///< isovalue (value units)
  InsideIs inside = InsideIs::kAbove;
  double stiffness_n_per_m = 800.0;   ///< K [N/m] of device motion
  double damping_n_s_per_m = 1.0;     ///< B [N s/m]
  double rate_hz = 1000.0;            ///< servo rate [Hz]
  double force_limit_n = 3.3;         ///< |F| saturation [N], direction kept
  double world_per_device = 1.0;      ///< workspace scale: world [m] per device [m]
  double max_reach_m = 10.0;          ///< HIP farther than this from the volume centre: fault
  // Blezek-Robb only:
  int inch_iterations = 4;            ///< inching steps per tick
  double inch_step_voxels = 0.5;      ///< longest inching step [voxels]
  double central_h_voxels = 0.5;      ///< central-difference half step [voxels]
};

/// Avila and Sobierajski, "A haptic interaction method for volume visualization",
/// IEEE Visualization 1996: forces straight from the density field, one trilinear sample
/// per tick. Their force transfer functions are left open for isosurfaces; the choices:
/// - stiffness force along the outward normalized gradient at the HIP, with the
///   penetration estimated from the density: d_est = (f(HIP) - tau) / |grad f(HIP)|
///   (first order, world [m]) while f(HIP) > tau, else 0: F_s = K d_est N;
/// - motion-retarding force F_r = -B v (the full HIP velocity) while inside, else 0;
/// - the gradient is the trilinear blend of the published gradient samples;
/// - the reported contact point (vhip_m) is HIP + d_est N, the estimated surface point.
/// It has no memory: starting inside gives a force, and thin walls are pushed through.
class AvilaRenderer final : public Renderer {
 public:
  explicit AvilaRenderer(const BaselineParams& p) : p_(p) {}
  const char* name() const override { return "Avila-Sobierajski"; }
  void reset() override { started_ = false; }
  using Renderer::tick;
  HriTick tick(const FieldView& field, const Vec3& hip_world_m, double dt_s) override;

 private:
  BaselineParams p_;
  Vec3 prev_hip_;
  bool started_ = false;
};

/// Blezek and Robb, "Haptic rendering of isosurfaces directly from medical images",
/// Medicine Meets Virtual Reality 1999: a surface contact point (VHIP) kept on the
/// isosurface and "inched" along it each tick until HIP - VHIP is parallel to the
/// surface normal. Choices the paper leaves open:
/// - contact starts when the HIP crosses into the object; the VHIP starts at the crossing
///   on the segment previous HIP -> HIP (8 bisection steps);
/// - each tick: up to inch_iterations steps; a step moves the VHIP along the tangential
///   part of HIP - VHIP (at most inch_step_voxels), then projects it back onto the
///   isosurface with one Newton step along the gradient; stops when the tangential part
///   is below 1e-3 voxel;
/// - normals and gradients by central differences of the trilinear value field with a
///   half step of central_h_voxels (6 samples each: "several central-difference
///   gradients per tick");
/// - where the gradient vanishes the inching fails: zero force that tick (the paper's
///   "haptically transparent" failure), contact kept;
/// - contact ends when the HIP is outside; F = -K (HIP - VHIP) - B v_N, a wall that
///   only pushes, saturated at the force limit, as in HriRenderer.
class BlezekRenderer final : public Renderer {
 public:
  explicit BlezekRenderer(const BaselineParams& p) : p_(p) {}
  const char* name() const override { return "Blezek-Robb"; }
  void reset() override { started_ = false; contact_ = false; }
  using Renderer::tick;
  HriTick tick(const FieldView& field, const Vec3& hip_world_m, double dt_s) override;

 private:
  double excess(double v) const {
    return iso_excess(v, p_.tau, p_.inside);
  }
  /// Outward gradient of the excess by central differences [excess/m]; zero if undefined.
  Vec3 gradient(const FieldView& field, const Vec3& x) const;
  BaselineParams p_;
  Vec3 vhip_;
  Vec3 prev_hip_;
  bool started_ = false;
  bool contact_ = false;
};

}  // namespace isotouch::servo
