// hri.h - Direct Haptic Rendering of Isosurface by Intermediate Representation (HRI).
//
// Source: "Direct Haptic Rendering of Isosurface by Intermediate Representation",
// Figure 2 (servo algorithm), eqs. 1-3, §3.1 (surface effects by constraining the VHIP),
// §3.2 (plane update every n ticks), §3.3 (force shading, recovery time). The renderer
// reads a published SampleField only; tick() allocates nothing, takes no lock and makes
// no syscall.
#pragma once
#include <cstdint>

#include "renderer.h"

namespace isotouch::servo {

/// How p is found on the segment VHIP -> HIP at a plane update.
enum class Intersection : std::uint8_t {
  kLinear,     ///< the paper: linear interpolation of the two end values
  kSecant,     ///< `intersection_steps` regula-falsi (Illinois) steps on the trilinear field
  kBisection,  ///< `intersection_steps` bisection steps, then linear inside the last bracket
};

/// Where N comes from at a plane update.
enum class NormalSource : std::uint8_t {
  kSamples,         ///< trilinear blend of the published gradient samples
  kCentral,         ///< central differences of the trilinear value at p, h = 1/2 voxel (the paper)
  kTrilinearExact,  ///< the exact gradient of the trilinear interpolant (reference runs)
};

/// Which HRI servo runs.
enum class Variant : std::uint8_t {
  kRobust,  ///< the default: Figure 2 plus the departures listed on HriRenderer
  kPaper,   ///< Figure 2 exactly as printed (see HriRenderer), for Table 1 and reports
};

/// Surface effects by constraining the VHIP (§3.1, after Salisbury et al. 1995).
struct SurfaceFriction {
  double mu_s = 0;                 ///< static coefficient: VHIP holds while |F_t| <= mu_s |F_n|
  double mu_d = 0;                 ///< dynamic coefficient: sliding keeps |F_t| = mu_d |F_n|
  double viscous_n_s_per_m = 0;    ///< viscous friction: the VHIP drifts at |F_t| / b_v
  bool any() const { return mu_s > 0 || mu_d > 0 || viscous_n_s_per_m > 0; }
};

/// HRI parameters. Stiffness and damping act in device space [m of device motion].
struct HriParams {
  Variant variant = Variant::kRobust;  ///< robust (default) or the paper's Figure 2 as printed
  double tau = 0.0;                  ///< isovalue (value units)
  InsideIs inside = InsideIs::kAbove;
  double stiffness_n_per_m = 800.0;  ///< K [N/m] of device motion (eq. 3)
  double damping_n_s_per_m = 1.0;    ///< B [N s/m] along d (eq. 3)
  int plane_update_period = 5;       ///< n: the plane is recomputed every n ticks (§3.2)
  double rate_hz = 1000.0;           ///< servo rate [Hz]; the period T = 1/rate
  double force_limit_n = 3.3;        ///< |F| is saturated here, direction kept [N]
  double world_per_device = 1.0;     ///< workspace scale: world [m] per device [m]
  double max_reach_m = 10.0;         ///< a HIP farther than this from the volume centre is a fault [m]
  Intersection intersection = Intersection::kLinear;
  int intersection_steps = 4;        ///< secant / bisection steps
  NormalSource normal = NormalSource::kSamples;
  SurfaceFriction friction;
  bool force_shading = false;        ///< §3.3: shading plane from the normal at the previous VHIP
  double recovery_time_s = 0;        ///< §3.3: > 0 turns recovery time on [s]
};

/// The HRI servo renderer (Figure 2).
///
/// Choices the paper leaves open, and what is done here:
/// - Plane update period: Figure 2 as printed checks `c >= n` before incrementing,
///   which recomputes every n+1 ticks; §3.2 says the plane updates at 1/n of the servo
///   rate ("five times slower" in Table 1). We follow §3.2: c is incremented first, so
///   with n = 1 the plane is recomputed every tick.
/// - LinearInterpolation(VHIP, HIP, tau): t = (tau - f(VHIP)) / (f(HIP) - f(VHIP)),
///   clamped to [0, 1]. The secant and bisection options refine t on the trilinear field
///   (the two ends bracket tau). When the VHIP is itself inside (embedded, Figure 5b) the
///   ends do not bracket tau and the linear rule would extrapolate; p is then the surface
///   point found from the VHIP along its outward normal, searched no farther than twice
///   the first-order depth plus a quarter voxel (16 bisection steps), else the VHIP.
/// - SurfaceNormal(p): see NormalSource; negated for InsideIs::kAbove so N points
///   outward. Where that gradient is zero or not finite: the unit vector from HIP to
///   VHIP, else the previous normal, else +z.
/// - Force sign: the paper writes F = K d - B v_d with d = HIP - VHIP, which is the
///   force the user exerts on the surface. The force on the device must push the HIP
///   back toward the VHIP, so we render F = -K d - B v_d, with v_d the HIP velocity
///   component along N (d's rate with the plane held; it has no spike at plane updates).
///   The wall only pushes: a net pull (F . N < 0, from damping while withdrawing) is
///   clipped to zero. |F| is saturated at force_limit_n keeping its direction.
/// - Friction (§3.1): the VHIP is held on the plane (the contact point from the tick
///   before, re-projected when the plane changes) while the tangential spring force
///   K |VHIP - VHIP_free| stays within mu_s K |d_n|; beyond it the VHIP slides, trailing
///   the frictionless VHIP_free (eq. 2) at the distance that makes |F_t| = mu_d |F_n|,
///   and sticks again once that distance is not exceeded. Viscous friction moves the held
///   VHIP toward VHIP_free by K T / (b_v + K T) of the gap per tick (backward Euler of
///   b_v dx/dt = K (free - x)), so steady sliding at speed v gives |F_t| = b_v v.
/// - Force shading (§3.3, after Ruspini et al. 1997): a constraint plane through the
///   previous VHIP with the normal there (same NormalSource) first projects the HIP to a
///   temporary HIP; the true plane then projects that to the final VHIP. Costs one normal
///   per tick.
/// - Recovery time (§3.3, after Mark et al. 1996): when a plane update finds the previous
///   VHIP embedded (inside the object) and the force magnitude would jump up, the force
///   keeps the new direction and its magnitude ramps linearly from the previous magnitude
///   to the new value over recovery_time_s.
/// - No pop-through (beyond the paper): when both VHIP and HIP are outside but the
///   segment VHIP -> HIP is longer than half a voxel, or when a plane update finds the
///   HIP outside again, the segment is marched (half-voxel steps, at most 4096, then
///   bisection) for a crossing of the isosurface; if it crosses, the HIP went through a
///   thin wall and the plane is placed at the first crossing instead of being dropped.
/// - Device faults: a non-finite HIP, or one farther than max_reach_m from the volume
///   centre, gives zero force and fault = true. After a non-finite HIP the contact state
///   is kept; after an absurd one the renderer restarts (VHIP = HIP, no plane) at the
///   next sane HIP, so it can neither pull nor march across the world.
class HriRenderer final : public Renderer {
 public:
  explicit HriRenderer(const HriParams& params) : params_(params) {}

  const char* name() const override { return "HRI"; }
  /// Forget contact state (next tick starts as the first tick of a simulation).
  void reset() override;

  /// One servo tick. @param field the published samples; @param hip_world_m the HIP
  /// in world [m]. A non-finite HIP yields zero force and fault = true; the state is
  /// kept so contact resumes when sane input returns.
  /// @param dt_s measured period [s]; <= 0 or non-finite: the nominal 1 / rate_hz.
  using Renderer::tick;
  HriTick tick(const SampleField& field, const Vec3& hip_world_m, double dt_s) override;

  const HriParams& params() const { return params_; }
  const VirtualPlane& plane() const { return plane_; }
  const Vec3& vhip() const { return vhip_; }
  int counter() const { return c_; }
  bool sliding() const { return sliding_; }

  /// Signed excess over the isovalue: > 0 inside, <= 0 outside; NaN counts as outside.
  double excess(double value) const {
    const double e = params_.inside == InsideIs::kAbove ? value - params_.tau
                                                        : params_.tau - value;
    return e == e ? e : -1.0;
  }

  /// Outward unit normal at x from the configured NormalSource, or `fallback`.
  Vec3 outward_normal(const SampleField& field, const Vec3& x, const Vec3& fallback) const;

 private:
  VirtualPlane compute_plane(const SampleField& field, double f_vhip, double f_hip,
                             const Vec3& hip) const;
  VirtualPlane plane_at(const SampleField& field, const Vec3& p, const Vec3& hip) const;
  /// First isosurface crossing on the segment a -> b, a outside (see class docs).
  bool first_crossing(const SampleField& field, const Vec3& a, const Vec3& b, Vec3& p) const;
  Vec3 constrain(const Vec3& hip, const Vec3& free_vhip);
  /// The segment a -> b is longer than half a voxel (worth searching for a crossing).
  static bool long_step(const SampleField& field, const Vec3& a, const Vec3& b);

  HriParams params_;
  VirtualPlane plane_;
  Vec3 vhip_;
  Vec3 prev_hip_;
  double prev_force_mag_ = 0;
  int c_ = 0;
  int recovery_ticks_left_ = 0;
  int recovery_ticks_ = 0;
  double recovery_from_n_ = 0;
  bool started_ = false;
  bool resync_ = false;
  bool sliding_ = false;
  bool was_contact_ = false;
};

}  // namespace isotouch::servo
