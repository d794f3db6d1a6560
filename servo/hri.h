// hri.h - Direct Haptic Rendering of Isosurface by Intermediate Representation (HRI).
//
// Source: "Direct Haptic Rendering of Isosurface by Intermediate Representation",
// Figure 2 (servo algorithm), eqs. 1-3, §3.1-3.2. The renderer reads a published
// SampleField only; tick() allocates nothing, takes no lock and makes no syscall.
#pragma once
#include <cstdint>

#include "sample_field.h"
#include "vec3.h"

namespace isotouch::servo {

/// Which side of the isovalue is "inside" the object.
enum class InsideIs : std::uint8_t {
  kAbove,  ///< value > tau is inside (CT density, the paper's B(v) = 1)
  kBelow,  ///< value < tau is inside (signed distance fields, negative inside)
};

/// HRI parameters. Stiffness and damping act in device space [m of device motion].
struct HriParams {
  double tau = 0.0;                  ///< isovalue (value units)
  InsideIs inside = InsideIs::kAbove;
  double stiffness_n_per_m = 800.0;  ///< K [N/m] of device motion (eq. 3)
  double damping_n_s_per_m = 1.0;    ///< B [N s/m] along d (eq. 3)
  int plane_update_period = 5;       ///< n: the plane is recomputed every n ticks (§3.2)
  double rate_hz = 1000.0;           ///< servo rate [Hz]; the period T = 1/rate
  double force_limit_n = 3.3;        ///< |F| is saturated here, direction kept [N]
  double world_per_device = 1.0;     ///< workspace scale: world [m] per device [m]
  double max_reach_m = 10.0;         ///< a HIP farther than this from the volume centre is a fault [m]
};

/// The virtual plane (N, p) of eq. 1: N . (x - p) = 0, N the unit outward normal.
struct VirtualPlane {
  Vec3 n;              ///< unit outward normal (volume frame)
  Vec3 p;              ///< point on the isosurface (world [m])
  bool valid = false;  ///< false = the paper's VirtualPlane = (0, 0)
};

/// What one servo tick produced.
struct HriTick {
  Vec3 force_n;               ///< force on the device [N], device axes (= volume axes)
  Vec3 vhip_m;                ///< VHIP after this tick, world [m]
  VirtualPlane plane;         ///< the plane in use after this tick
  double penetration_m = 0;   ///< |HIP - VHIP| in world [m] while in contact, else 0
  bool contact = false;       ///< a force was rendered from the plane this tick
  bool plane_update = false;  ///< the plane was (re)computed this tick
  bool saturated = false;     ///< |F| hit force_limit_n
  bool fault = false;         ///< non-finite HIP or force: zero force was sent
};

/// The HRI servo renderer (Figure 2).
///
/// Choices the paper leaves open, and what is done here:
/// - Plane update period: Figure 2 as printed checks `c >= n` before incrementing,
///   which recomputes every n+1 ticks; §3.2 says the plane updates at 1/n of the servo
///   rate ("five times slower" in Table 1). We follow §3.2: c is incremented first, so
///   with n = 1 the plane is recomputed every tick.
/// - LinearInterpolation(VHIP, HIP, tau): t = (tau - f(VHIP)) / (f(HIP) - f(VHIP)),
///   clamped to [0, 1] (0 where the denominator vanishes, e.g. an embedded VHIP).
/// - SurfaceNormal(p): the trilinear blend of the published gradient samples at p,
///   negated for InsideIs::kAbove so N points outward. Where that gradient is zero or
///   not finite: the unit vector from HIP to VHIP, else the previous normal, else +z.
/// - Force sign: the paper writes F = K d - B v_d with d = HIP - VHIP, which is the
///   force the user exerts on the surface. The force on the device must push the HIP
///   back toward the VHIP, so we render F = -K d - B v_d, with v_d the HIP velocity
///   component along N (d's rate with the plane held; it has no spike at plane updates).
///   The wall only pushes: a net pull (F . N < 0, from damping while withdrawing) is
///   clipped to zero. |F| is saturated at force_limit_n keeping its direction.
/// - No pop-through (beyond the paper): when both VHIP and HIP are outside but the
///   segment VHIP -> HIP is longer than half a voxel, or when a plane update finds the
///   HIP outside again, the segment is marched (half-voxel steps, at most 4096, then
///   bisection) for a crossing of the isosurface; if it crosses, the HIP went through a
///   thin wall and the plane is placed at the first crossing instead of being dropped.
/// - Device faults: a non-finite HIP, or one farther than max_reach_m from the volume
///   centre, gives zero force and fault = true. After a non-finite HIP the contact state
///   is kept; after an absurd one the renderer restarts (VHIP = HIP, no plane) at the
///   next sane HIP, so it can neither pull nor march across the world.
class HriRenderer {
 public:
  explicit HriRenderer(const HriParams& params) : params_(params) {}

  /// Forget contact state (next tick starts as the first tick of a simulation).
  void reset();

  /// One servo tick. @param field the published samples; @param hip_world_m the HIP
  /// in world [m]. A non-finite HIP yields zero force and fault = true; the state is
  /// kept so contact resumes when sane input returns.
  HriTick tick(const SampleField& field, const Vec3& hip_world_m);

  const HriParams& params() const { return params_; }
  const VirtualPlane& plane() const { return plane_; }
  const Vec3& vhip() const { return vhip_; }
  int counter() const { return c_; }

  /// Signed excess over the isovalue: > 0 inside, <= 0 outside; NaN counts as outside.
  double excess(double value) const {
    const double e = params_.inside == InsideIs::kAbove ? value - params_.tau
                                                        : params_.tau - value;
    return e == e ? e : -1.0;
  }

 private:
  VirtualPlane compute_plane(const SampleField& field, double f_vhip, double f_hip,
                             const Vec3& hip) const;
  VirtualPlane plane_at(const SampleField& field, const Vec3& p, const Vec3& hip) const;
  /// First isosurface crossing on the segment a -> b, a outside (see class docs).
  bool first_crossing(const SampleField& field, const Vec3& a, const Vec3& b, Vec3& p) const;

  HriParams params_;
  VirtualPlane plane_;
  Vec3 vhip_;
  Vec3 prev_hip_;
  int c_ = 0;
  bool started_ = false;
  bool resync_ = false;
};

}  // namespace isotouch::servo
