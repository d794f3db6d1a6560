// hri.h - Direct Haptic Rendering of Isosurface by Intermediate Representation (HRI).
//
// Source: "Direct Haptic Rendering of Isosurface by Intermediate Representation",
// Figure 2 (servo algorithm), eqs. 1-3, §3.1 (surface effects by constraining the VHIP),
// §3.2 (plane update every n ticks), §3.3 (force shading, recovery time). The renderer
// reads the published field through core::FieldView only; tick() allocates nothing, takes no lock and makes
// no syscall.
#pragma once
#include "isotouch/servo/core_names.h"
#include <cstdint>

#include "isotouch/servo/renderer.h"

namespace isotouch::servo {

/// How p is found on the segment VHIP -> HIP at a plane update.
enum class Intersection : std::uint8_t {
  kLinear,     ///< the paper (Variant::kPaper always): linear interpolation of the two end values
  kSecant,     ///< `intersection_steps` regula-falsi (Illinois) steps on the trilinear field
  kBisection,  ///< `intersection_steps` bisection steps, then linear inside the last bracket
};

/// Where N comes from at a plane update.
enum class NormalSource : std::uint8_t {
  kSamples,         ///< trilinear blend of the published gradient samples
  kCentral,         ///< central differences of the trilinear value at p, h = 1/2 voxel (the paper; Variant::kPaper always)
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
  /// Robust variant: cut-off of the first-order low-pass on the HIP velocity [Hz]
  /// (0 = the raw backward difference). See HriRenderer, "Velocity". 200 Hz: at 1 kHz
  /// alpha = 0.56 (63 % of a step in 1.3 ticks); the Colgate-Schenkel experiments of
  /// `isotouch stability` still hold with it.
  double velocity_cutoff_hz = 200.0;
  /// Robust variant: while a plane is held, a HIP that moved faster than this [m/s of
  /// device motion] since the last sane tick is a fault and the renderer resyncs.
  double max_speed_m_s = 100.0;
  /// Robust variant: most field samples one march along a segment may take (then bisection).
  int march_budget = 128;
  /// Robust variant, edits: the time one edit's material took to remove [s]. A brush applied
  /// every T seconds removes what the tool cut in those T seconds at once (the scenes' drill:
  /// every_ticks / rate_hz; the app's button drill likewise); the force step the edit causes
  /// (the force sent the tick before minus this tick's target) is eased out linearly over T,
  /// added to the target, so the force follows the material as it was removed, not one step
  /// per edit (no dip and recovery at the edit rate). The ease's rate is the edit's own
  /// |step| / T [N/s] (no fixed per-tick cap); a breakthrough is felt at most T late. An edit
  /// is a new snapshot version (FieldView::version); see HriRenderer, "Edits". 0 (any value
  /// not > 0, NaN included) turns the edit handling off: a new snapshot is then read at the
  /// next plane update like any other, and the force steps. 0.01 s: the shipped scenes' 10
  /// ticks at 1 kHz.
  double edit_period_s = 0.01;
  /// Robust variant: radius of a spherical tool [m, world]; 0 = a point (the paper). The
  /// HIP is the tool's centre; see HriRenderer, "Spherical tool".
  double tool_radius_m = 0.0;
  /// Robust variant: the two common ticks (contact behind a held plane with no update due,
  /// free motion outside on a short step) take a short way, the general path's arithmetic
  /// with each point computed once; with edits tracked, a free HIP that stays in a cell
  /// whose 8 corners are all outside reads no sample (no point of the cell is inside: the
  /// trilinear value is a blend of its corners). false: every tick the general path (the
  /// same bits; tests compare the two).
  bool short_way = true;
};

/// One constraint plane of the spherical tool: the tool centre x is held where
/// n . (x - p) >= radius, (n, p) the outward normal and a point of the isosurface.
struct ToolPlane {
  Vec3 n;
  Vec3 p;
};

/// The HRI servo renderer (Figure 2).
///
/// Two variants (HriParams::variant):
///
/// Variant::kPaper is Figure 2 exactly as printed: the counter is checked before it is
/// incremented (`IF c >= n THEN c = 0 ... ELSE c = c + 1`, so the plane is recomputed
/// every n+1 ticks); p = LinearInterpolation(VHIP, HIP, tau) (t clamped to [0, 1], and
/// t = 0 where it is not finite) always, whatever `intersection` says; N = SurfaceNormal(p)
/// by central differences at p (NormalSource::kCentral) always, whatever `normal` says
/// (the paper: N is "approximated by using central difference"). Guards added to the
/// printed figure, all shared with the robust variant (see "Common to both"): that t
/// clamp, a net pulling force clipped to zero (the wall pushes, never pulls), |F|
/// saturated at force_limit_n, a non-finite |F| or HIP sent as zero force; the plane is
/// dropped at an update that finds the HIP outside; no march for thin walls, no search
/// for the surface from an embedded VHIP, no jump or budget fault; v_d from the backward
/// difference of the HIP at the nominal period 1/rate; the §3.1 friction and §3.3
/// shading / recovery options as described below for the paper (recovery only when an
/// update finds the previous VHIP embedded and the force would rise). Used by Table 1
/// and `isotouch report` to show what each departure of the robust variant buys.
///
/// Common to both:
/// - Force sign: the paper writes F = K d - B v_d with d = HIP - VHIP, which is the
///   force the user exerts on the surface. The force on the device must push the HIP
///   back toward the VHIP, so we render F = -K d - B v_d, with v_d the HIP velocity
///   component along N (d's rate with the plane held; it has no spike at plane updates).
///   The wall only pushes: a net pull (F . N < 0, from damping while withdrawing) is
///   clipped to zero. |F| is saturated at force_limit_n keeping its direction.
/// - SurfaceNormal(p): see NormalSource; negated for InsideIs::kAbove so N points
///   outward. Where that gradient is zero or not finite: the unit vector from HIP to
///   VHIP, else the previous normal, else +z.
/// - Friction (§3.1): the VHIP is held on the plane (the contact point from the tick
///   before, re-projected when the plane changes) while the tangential spring force
///   K |VHIP - VHIP_free| stays within mu_s K |d_n|; beyond it the VHIP slides, trailing
///   the frictionless VHIP_free (eq. 2) at the distance that makes |F_t| = mu_d |F_n|,
///   and sticks again once that distance is not exceeded. The Coulomb cone is tested on
///   the held point first; viscous friction then moves the VHIP (only when the cone lets
///   it move, or when there is no Coulomb friction) toward that target by
///   K T / (b_v + K T) of the gap per tick (backward Euler of b_v dx/dt = K (x* - x)),
///   so steady sliding at speed v gives |F_t| = mu_d |F_n| + b_v v.
/// - Device faults: a non-finite HIP, or one farther than max_reach_m from the volume
///   centre, gives zero force and fault = true. After a non-finite HIP the contact state
///   is kept; after an absurd one the renderer restarts (VHIP = HIP, no plane) at the
///   next sane HIP, so it can neither pull nor march across the world.
///
/// Variant::kRobust (the default) departs from Figure 2 as follows, each for a fault a
/// user would feel:
/// - Update period: c is incremented first, so the plane is recomputed every n ticks as
///   §3.2 says (n = 1: every tick). It is also recomputed early, on the tick where the
///   VHIP would move more than half a voxel along the plane from where the plane was
///   last computed: a stale plane cannot carry the VHIP into the air or into a wall.
/// - Samples only when the method needs them: while the HIP is behind a held plane and
///   no update is due, the tick reads no sample (eq. 2 and 3 need none).
/// - Entry test in front of a held plane: a HIP in front of the plane is not in contact
///   with it; its value is read and, if it entered an object (or crossed a thin one on
///   a long step), a new plane is made from the VHIP -> HIP segment at once; otherwise
///   the plane is dropped. Figure 2 keeps the plane for up to n ticks and feels nothing.
/// - God-object constraint (Zilles and Salisbury 1995): at an update that finds the HIP
///   outside but behind the plane, the plane is dropped only when the VHIP is outside
///   and the segment VHIP -> HIP does not cross the isosurface (the surface curved away).
///   If the segment enters the object, or the VHIP is embedded, the HIP left through a
///   far side and the near surface still constrains it: the plane is placed at the first
///   crossing (or at the surface found from the embedded VHIP).
/// - Contact goes on while the HIP is inside: if the HIP is inside but in front of the
///   held plane (a concave corner, a rough scan) the plane is recomputed at once from the
///   VHIP -> HIP segment even when the VHIP is embedded, and if a new plane (this or any
///   update) still leaves the inside HIP in front of it, the plane is put at the surface
///   found from the HIP along its outward normal (bounded as below); if none is found (a
///   noisy scan, coarse voxels), on a plane along the outward normal at the HIP (the held
///   normal if that one faces away from it) at the first-order depth e / |grad|, at most
///   4 voxels; else the plane of the tick before is kept. A plane held on the tick before
///   is thus never dropped while the HIP is inside (god-object); the force change is
///   ramped as any update (recovery time). Figure 2 renders zero force there (head CT:
///   1.74 N -> 0 in one tick, 3 mm inside bone).
/// - Embedded VHIP (Figure 5b): p is the surface point found from the VHIP along its
///   outward normal, no farther than twice the first-order depth plus a quarter voxel
///   (16 bisection steps), else the VHIP (the linear rule would extrapolate). A shallow
///   embedding (at most 0.05 voxel: a chord, or a plane held over a curved surface) is
///   stepped out along the held normal by 1.5 times the first-order depth, at most 0.05
///   voxel, instead (no search; p is then outside by at most 0.05 voxel).
/// - Thin walls on long steps: when both ends are outside and the segment is longer than
///   half a voxel, it is marched (half-voxel steps, at most march_budget samples, longer
///   steps beyond that; then 20 bisection steps) for a first crossing.
/// - Jumps: while a plane is held, a HIP that moved faster than max_speed_m_s since the
///   last sane tick is a fault (zero force) and the renderer resyncs at the next tick.
/// - Velocity: the measured period dt_s (else 1/rate) is used; the backward difference
///   is filtered by a first-order low-pass (an exponential moving average, cut-off
///   velocity_cutoff_hz = 200 Hz by default, 0 = unfiltered; alpha = dt / (dt + 1/(2 pi
///   f_c))), and the estimate restarts at zero after any fault or resync (the time of
///   lost ticks is added to the next dt), so lost ticks give no damping spike (the paper's
///   backward difference at the nominal period gave 1.30 N for a 0.30 N spring after 50
///   lost ticks).
/// - Recovery time (§3.3, after Mark et al. 1996), when recovery_time_s > 0: EVERY plane
///   creation or update, and the first contact tick after a fault (zero force was sent),
///   that changes |F| by more than 1 % of the force limit starts a ramp: |F| goes
///   linearly from the magnitude sent the tick before to the new value over
///   recovery_time_s, in the new direction (Figure 2 + Mark et al. only ramp an embedded
///   update upward; a plane made after free ticks then jumps 0 -> K d). The ramp runs on
///   accumulated time, each tick adding its measured period clamped to [0, 2/rate]
///   (never the time of lost ticks), so a ramp started after 50 lost ticks or on one
///   jittery 10 us period still lasts recovery_time_s (a length in ticks from one
///   measured period gave 1 tick, or 1800).
/// - Normals on thin structures (NormalSource::kSamples): where the blend of the gradient
///   samples turns more than 30 deg from the gradient of the trilinear values (the two
///   faces of a plate one or two voxels thick cancel in the blend), the latter is the
///   normal. A shallow embedding's step out is taken only if it reaches the outside
///   (else the embedded search). The "surface curved away" test marches fifth-voxel
///   steps (a coarse plate's trilinear inside can be thinner than half a voxel).
/// - Proxy path: a new plane whose contact point is reached from an outside VHIP only
///   through material (7 points of the segment, deeper than 0.05 voxel first order; any
///   depth for a plane facing away from the held one) lies on another sheet; the held
///   plane stays while the HIP is behind it (not on edit ticks). Then, on every tick that
///   held a plane before and moves the proxy more than a quarter voxel (an update, a drop,
///   a slide), the proxy's straight path is checked at 64 or more points
///   (keep_proxy_outside): one that enters material and comes out again, goes deeper than
///   an embedded VHIP started, or (HIP outside only) leaves an embedded VHIP back through
///   the held plane by more than a quarter voxel passes through a thin wall (a tapering
///   edge on coarse voxels, where the trilinear inside is a sliver; with the HIP inside a
///   rib one or two voxels thick, the plane found from the HIP lies on the nearer, far
///   face; with the HIP inside, a proxy leaving an embedded VHIP deeper follows the
///   surface the HIP presses under on a noisy scan): the proxy stays at the entry (from an
///   embedded VHIP: the surface along the held normal) on the surface's plane there, else
///   on the held normal, else on the plane facing the HIP, whichever keeps it out of the
///   material. A path that ends inside at its deepest point is a chord under a plane held
///   over a curved surface and is let through (the embedded search brings it out).
/// - Thin features (the side the contact entered from): with the HIP inside past the middle
///   of the feature under the held plane (the material behind the HIP, along the held
///   normal, ends within the HIP's depth behind that plane: a fin, a branch, a rib pressed
///   beyond half its thickness), the plane iteration is unstable: each update's plane,
///   tilted over the feature's rounded edge, projects the HIP farther round it, and within
///   tens of milliseconds the proxy wraps to the far side and the force falls to zero well
///   below the limit (a god-object does the same: past the middle the far face is the
///   nearer). So, while the HIP is inside, an update whose plane turns more than
///   kEntryConeDeg from the normal the contact entered with (entry_n_: the normal of the
///   new contact, refreshed at every update that turns that far with the HIP not past the
///   middle) keeps the held plane if the HIP is past the middle and behind it: the proxy
///   stays on the entry side and the force grows with the press up to the limit. The turn
///   is also checked along the new plane's normal: a HIP at or past the middle of the chord
///   that way is no nearer the new face than the opposite one (the plane iteration carrying
///   the proxy round; at n = 1 it runs every tick and turned entry_n_ with it before the HIP
///   reached the middle along it). On a thin feature only (its far face within the HIP's
///   depth plus two of the smallest voxels behind the HIP along -entry_n_, or the feature at
///   most twice limit / K thick: its middle within the press the limit allows), the side is also held
///   when the proxy went farther across entry_n_ than the HIP since entry_n_ was set (the
///   iteration carrying it round a crest); convex bulk material does that too, by
///   R / (R - depth), and held there the plane kept its normal round a sphere. That turn
///   (the proxy a quarter voxel farther across than the HIP, on a thin feature) is held
///   also while the plane stays within the cone: where the contact's normal came 25 deg
///   off a crest's, the iteration carried the proxy round in steps inside the cone of it.
///   And a HIP past the middle along entry_n_ at its deepest since entry_n_ was set holds
///   the side at a turn too (checked there, no read before the turn): stroked across a
///   cylinder, the HIP pressed past its axis is short of the middle along a tilted entry_n_
///   again. While held, the held plane's point is lifted to the face
///   found from the HIP along its normal where that face lies in front of it (face_along):
///   a held plane tilted from the face slid the proxy down it on a stroke along the feature.
///   It is lowered to that face only with the HIP short of the middle along the held normal
///   and the material under the face as thick along it (within half a voxel) as under the
///   point where the side was taken: a wall falling away under the stroke, not a crest's
///   rounded corner (never lowered, the head CT's hold ended releasing 2.4 N in one tick). Not on
///   edit ticks. In bulk material (no far side within the depth) nothing changes.
/// - Release fade, when recovery_time_s > 0: a tick that ends contact while the force sent
///   the tick before exceeds 1 % of the limit (an update dropped the plane under a HIP still
///   behind it, a wall drilled away) fades that force out along its direction over
///   recovery_time_s; new contact or a fault ends it. The proxy is on no surface while it
///   fades: contact = false, penetration 0 (a run's figures count the release at the tick
///   contact ended, with the force sent then, whatever the fade does after it).
/// - Force shading (§3.3, after Ruspini et al. 1997): a constraint plane through the
///   previous VHIP with the normal there first projects the HIP to a temporary HIP; the
///   true plane then projects that onto itself, always: the final VHIP lies on the true
///   plane (the paper's version leaves it at the temporary HIP when that is in front).
/// - Edits, when edit_period_s > 0: a tick whose snapshot has
///   another FieldView::version than the last sane tick's is an edit tick. On it the plane
///   is re-evaluated at once (not at the next n-tick update) with the update rules above,
///   reading the VHIP's value and |grad| from the new snapshot (nothing cached from the old
///   one); with the VHIP outside and the HIP inside, p is the first crossing on the segment
///   VHIP -> HIP (the march for thin walls below) rather than the linear rule: a carve may
///   leave the VHIP far in the air, even in a uniform brick whose tile reads the isovalue
///   itself (p = VHIP by the linear rule). A VHIP in free motion that was outside in the
///   old snapshot and is inside the new one (material added over a hovering probe) counts
///   as an embedded contact point: the proxy is brought out to the new surface (before, the
///   VHIP's value cached from the old snapshot put a plane between VHIP and HIP at once, a
///   step). The edit's force step is eased (edit ease): the offset E = F sent the tick
///   before - this tick's target (the spring-damper force, saturated) is added to the
///   target and fades linearly to 0 over edit_period_s, the time the edit's material took
///   to remove: F_sent = target + E s, s = the ease's time left / edit_period_s. The
///   removal is spread over the period it happened in (a brush applied every T seconds
///   moves the surface by what T seconds of cutting removed), so under a steady drill
///   the surface's advance and the hand's push cancel and |F| stays level; the user's own
///   motion is felt at once through the target. The ease's rate is |E| / edit_period_s
///   (edit_ease_max_rate(): the largest of a run), and the surface is felt at most
///   edit_period_s late (a breakthrough too). While the offset pushes, the proxy shown
///   (HriTick::vhip_m) is the eased one, VHIP + E s * world_per_device / K, on the surface
///   as it recedes, and contact = true with the depth the force stands for: the material
///   is still going.
///   A running recovery ramp is folded into the ease and none starts on an edit tick. A
///   later edit during the ease starts a new one from the force sent. Carved under
///   the VHIP: the VHIP goes to the new surface at once and |F| eases down to K times the
///   new depth. Carved deeper than the HIP: the plane is dropped and |F| eases out along
///   the last force direction (the shown proxy on the receding surface). Added over
///   the VHIP: the VHIP comes out to the new surface (the embedded-VHIP search above; where
///   the addition is deeper than its reach, 8 voxels at most, a march out along the outward
///   normal at the VHIP, half-voxel steps, at most march_budget samples, then 20 bisection
///   steps) and |F| rises toward K times the new depth (saturated at the limit). With the
///   parameter 0 the version is never read (a run is bit for bit the run without the
///   feature), and without a version change nothing differs either. Fault ticks (zero
///   force) end the ease. The paper variant ignores versions (Figure 2 as printed).
///
/// Spherical tool (robust variant, tool_radius_m = r > 0). The HIP is the tool's centre,
/// the VHIP (proxy) the centre of a sphere of radius r kept outside the isosurface, the
/// HRI way with several intermediate planes (god-object with several active constraints):
/// the proxy is the point nearest the HIP with N_i . (x - q_i) >= r for every held plane
/// (N_i, q_i) (the best feasible projection onto at most three of them, closed-form
/// solves). At a plane update the cells of the trilinear field within r + 1 voxel of the
/// proxy are scanned (surface_scan: a cell holds the surface exactly when its corners
/// straddle tau; its point nearest the proxy by projections onto the linearised patch,
/// else its nearest edge crossing), and the planes are chosen nearest first: a surface
/// point already behind a chosen plane (or on it) cannot come nearer than r to a proxy
/// that plane holds, so only the points in front of every chosen plane add one (normal
/// from the point toward the proxy), at most kMaxToolPlanes. Walls of a groove, the three
/// faces of a corner and the blobs of a one-voxel plate each get their plane, including
/// those within the margin that the proxy reaches only while it slides. If the proxy so
/// placed moved more than a quarter voxel from the scan's centre, the scan is repeated
/// there (at most twice). Updates: every n ticks, and early when the proxy is more than
/// 0.2 voxel from the last scan's centre (so no surface beyond the scanned margin can come
/// within r), or on an edit tick. In free motion the tick reads no sample: the last scan
/// proved the surface no nearer than its nearest point, and the next scan comes when the
/// HIP has moved that far less r. Where the scan box would exceed kScanSide samples per
/// axis (a tool of many voxels), the nearest point is found by Newton steps along the
/// gradient instead (nearest_surface), as before. Force: F = K (proxy - HIP) - B v_u u,
/// u the unit push direction, no pull; an update that steps the force vector by more than
/// 1 % of the limit fades the step out over recovery_time_s (direction and magnitude);
/// edits ease as for the point. Thin features, as for the point (the side the contact
/// entered from; tool_hold_entry_side): at an update that turns the push direction (proxy -
/// HIP) more than kEntryConeDeg from the one the contact entered with (entry_n_), or leaves
/// the HIP clear of every new plane, while the sphere at the HIP overlaps the material (the
/// HIP inside, or a surface point within r: Newton search from the HIP, else a scan of the
/// cells within r), the planes of the tick before that face the entry side (within
/// kEntryConeDeg), with the new ones that do not face away from it, replace the new set if
/// they hold the HIP and the HIP is past the middle of the chord of material along entry_n_
/// through the point just behind the nearest surface point (the HIP itself when inside),
/// or was found past it since; else entry_n_ follows the turn. The hold ends when the
/// sphere leaves the material, the contact ends, an edit or a new radius comes. Other
/// updates read nothing for it. Friction and force shading do not apply to the tool (the
/// scene refuses them).
class HriRenderer final : public Renderer {
  friend struct HriRendererTest;  // tests/test_hri_entry_side.cpp: one hold_entry_side on a set state
 public:
  explicit HriRenderer(const HriParams& params);

  const char* name() const override { return "HRI"; }
  /// Forget contact state (next tick starts as the first tick of a simulation).
  void reset() override;

  /// One servo tick. @param field the published samples; @param hip_world_m the HIP
  /// in world [m]. A non-finite HIP yields zero force and fault = true; the state is
  /// kept so contact resumes when sane input returns.
  /// @param dt_s measured period [s]; <= 0 or non-finite: the nominal 1 / rate_hz.
  using Renderer::tick;
  HriTick tick(const FieldView& field, const Vec3& hip_world_m, double dt_s) override;

  const HriParams& params() const { return params_; }
  const VirtualPlane& plane() const { return plane_; }
  const Vec3& vhip() const { return vhip_; }
  int counter() const { return c_; }
  /// A new tool radius r [m, world] (0: the point) from the next tick on; call between ticks,
  /// on the thread that ticks (no allocation, no lock). The contact is re-seated, not
  /// carried over: the planes are dropped and found again at the next tick around the
  /// proxy (moved along the held plane's normal by the radius change, so that the same
  /// surface point is touched), while the force sent last is kept as the start of the
  /// recovery ramp (a new contact eases from it to K times the new depth over
  /// recovery_time_s) or of the release fade (no contact any more): no force step. A
  /// radius equal to the current one changes nothing. The robust variant only (the paper
  /// variant renders a point: ignored there); r not finite or < 0: ignored.
  void set_tool_radius(double r);
  /// Spherical tool: planes held after the last tick (0 = free motion).
  int tool_plane_count() const { return tool_plane_count_; }
  const ToolPlane& tool_plane(int i) const { return tool_planes_[i]; }
  /// Spherical tool: the centre nearest `hip` outside every held plane offset by the radius.
  Vec3 tool_solve(const Vec3& hip) const;
  /// Spherical tool: the isosurface point q nearest x within `reach` [m] and the outward
  /// normal there; false if none was found.
  bool nearest_surface(const FieldView& field, const Vec3& x, double reach, Vec3& q, Vec3& n) const;
  bool sliding() const { return sliding_; }
  /// Free ticks since construction that read no sample: the HIP stayed in a cell whose
  /// corners are all outside (robust point, quick_tick).
  std::uint64_t reads_skipped() const { return reads_skipped_; }
  /// The rate limits this renderer applied so far (a run's figures report them): ticks whose
  /// force the edit ease changed, the largest ease rate |E| / edit_period_s [N/s], and the
  /// ticks of release fades (recovery_time_s > 0). reset() keeps them.
  std::uint64_t edit_eased_ticks() const { return edit_eased_ticks_; }
  double edit_ease_max_rate() const { return edit_ease_max_rate_; }
  std::uint64_t release_fade_ticks() const { return release_fade_ticks_; }

  /// Signed excess over the isovalue: > 0 inside, <= 0 outside; NaN counts as outside.
  double excess(double value) const {
    return iso_excess(value, params_.tau, params_.inside);
  }

  /// Outward unit normal at x from the configured NormalSource, or `fallback`.
  Vec3 outward_normal(const FieldView& field, const Vec3& x, const Vec3& fallback) const;

 private:
  Vec3 outward_normal(const FieldView& field, const Vec3& x, const Vec3& fallback, double& grad_norm) const;
  /// What a tick writes as it goes: the force and the flags of HriTick. The tick's HriTick is
  /// built from it and the state (VHIP, plane) once, at the return (result()): a
  /// default-constructed HriTick (120 bytes) is zero-filled first, by a `rep stos` that
  /// cost a few ns of every tick.
  struct TickOut {
    Vec3 force_n;               ///< HriTick::force_n
    double penetration_m = 0;   ///< HriTick::penetration_m
    bool contact = false;       ///< HriTick::contact
    bool plane_update = false;  ///< HriTick::plane_update
    bool saturated = false;     ///< HriTick::saturated
    bool fault = false;         ///< HriTick::fault
    double force_mag = -1;      ///< |force| where contact_force knows it without a square root; < 0: not known
  };
  /// The HriTick of `t` with the VHIP after this tick and `plane`.
  /// (The plane from its components: copied as one struct GCC used `rep movsl`, a microcoded
  /// string copy on every tick.)
  HriTick result(const TickOut& t, const VirtualPlane& plane) const {
    const Vec3 n{plane.n.x, plane.n.y, plane.n.z}, p{plane.p.x, plane.p.y, plane.p.z};
    return HriTick{t.force_n, vhip_, VirtualPlane{n, p, plane.valid}, t.penetration_m, t.contact, t.plane_update,
                   t.saturated, t.fault};
  }
  /// The plane a robust tick reports: the held one; for the tool the first tool plane, if any.
  VirtualPlane reported_plane() const;
  VirtualPlane compute_plane(const FieldView& field, double f_vhip, double f_hip,
                             const Vec3& hip) const;
  VirtualPlane plane_at(const FieldView& field, const Vec3& p, const Vec3& hip) const;
  /// Surface point p from x (inside, excess e_x, |grad| grad_norm) along the outward normal
  /// at x, within twice the first-order depth plus a quarter voxel; false if none.
  /// `along`: search along this unit vector instead of the outward normal at x.
  bool surface_from(const FieldView& field, const Vec3& x, double e_x, double grad_norm, Vec3& p,
                    const Vec3* along = nullptr) const;
  /// Robust recovery ramp of the force vector (see "Recovery time"); returns the force to send.
  /// `before`: the force the ramp's trigger compares with (the target the plane of the tick
  /// before gives at this HIP; after a fault the target of the tick before). `ramped`: false
  /// where no ramp runs and `force` itself is returned.
  Vec3 ramp_force(const Vec3& force, bool plane_update, const Vec3& fallback_dir, const Vec3& before,
                  bool& ramped);
  /// ramp_force for a robust contact tick: `before` from the plane of the tick before
  /// (ramp_ref_) at this HIP, or the target of the tick before.
  Vec3 robust_ramp(const Vec3& force, const Vec3& hip, const Vec3& v, const TickOut& out, bool& ramped);
  /// Edit ticks: the surface point p from an embedded x (deeper than surface_from reaches)
  /// marched along the outward normal at x (half-voxel steps, at most march_budget samples,
  /// 20 bisection steps); false if none.
  bool march_out(const FieldView& field, const Vec3& x, Vec3& p) const;
  /// First isosurface crossing on the segment a -> b, a outside (see class docs).
  /// `step_voxels`: the march's step [voxels].
  bool first_crossing(const FieldView& field, const Vec3& a, const Vec3& b, Vec3& p, double step_voxels = 0.5) const;
  Vec3 constrain(const Vec3& hip, const Vec3& free_vhip, double dt);
  /// God-object guard (point, robust): if this tick's proxy move (onto the plane, or to
  /// the HIP when free) of more than a quarter voxel from an outside VHIP enters material,
  /// the plane is put at the first crossing instead (sets out.plane_update).
  /// See the class docs, "Proxy path" (the check of every long proxy move). f_vhip: the
  /// value at the VHIP when this tick read it already, else null.
  void keep_proxy_outside(const FieldView& field, const Vec3& hip, const VirtualPlane& held, double voxel,
                          const double* f_vhip, TickOut& out);
  /// The segment a -> b (excess e_a at a) passes through material: it enters (or, from an
  /// embedded a, goes deeper than 2 e_a) and comes out again, or ends inside at less than
  /// half its deepest excess (a path that ends inside at its deepest is a chord under a
  /// plane held over a curved surface: not counted); p: the entry point (a for "deeper").
  bool path_through(const FieldView& field, const Vec3& a, const Vec3& b, double e_a, double voxel, Vec3& p) const;
  /// Free motion from `hip` on: no plane, no ramp, no velocity history.
  void restart_at(const Vec3& hip);
  /// The contact state reset() and restart_at() both clear: plane, ramps, fades, tool planes.
  void clear_contact();
  HriTick tick_paper(const FieldView& field, const Vec3& hip);
  /// tick_general's plane change: the plane, its |grad| (last_grad_norm_), the anchor
  /// (eq. 2 from the HIP), the update counter reset, out.plane_update.
  void adopt_plane(const VirtualPlane& pl, const Vec3& hip, TickOut& out);
  /// In contact with the HIP inside but in front of the plane: the surface found from the
  /// HIP; else a plane along the outward normal at the HIP at the first-order depth; else
  /// the held plane if the HIP is behind it (see tick_general).
  void hold_hip_inside(const FieldView& field, const Vec3& hip, double e_hip, const VirtualPlane& held,
                       double held_grad_norm, double voxel, TickOut& out);
  /// The god-object test: the new plane's contact point (eq. 2) is reached from the VHIP only
  /// through material (a point of the segment deeper than 0.05 voxel to first order, at 7
  /// interior points; any material for a plane facing away from the held one). f_vhip: the
  /// value at the VHIP in this snapshot, if known (then a bound may answer without reads).
  bool reached_through_material(const FieldView& field, const Vec3& hip, const VirtualPlane& held,
                                double held_grad_norm, double voxel, const double* f_vhip) const;
  /// Thin features (see the class docs): after an update of tick_general that turned the
  /// plane more than kEntryConeDeg from entry_n_ with the HIP inside (hip_inside), keeps
  /// `held` where the HIP is past the feature's middle and behind it; else entry_n_ follows.
  void hold_entry_side(const FieldView& field, const Vec3& hip, bool hip_inside, const VirtualPlane& held,
                       double held_grad_norm, double voxel, TickOut& out);
  /// From the inside `hip`, the material ends both ways along n within `depth` plus a voxel
  /// [m], along -n no later than a quarter voxel after along n (fifth-voxel steps, at most
  /// march_budget samples in all): the HIP is past the middle of a thin feature.
  bool past_middle(const FieldView& field, const Vec3& hip, const Vec3& n, double depth, double voxel) const;
  /// Where the plane held now puts the proxy for `hip` (eq. 2; the HIP itself without a plane).
  Vec3 proxy_on_plane(const Vec3& hip) const {
    return plane_.valid ? hip + plane_.n * dot(plane_.n, plane_.p - hip) : hip;
  }
  /// Thin features: from the inside `hip` along unit n, the first point where the material
  /// ends within `reach` [m] (fifth-voxel steps, then 20 bisection steps; q the outside end
  /// of the bracket); false if none.
  bool face_along(const FieldView& field, const Vec3& hip, const Vec3& n, double reach, double voxel, Vec3& q) const;
  /// The robust tick after the short way: the general path (updates, entries, the god-object
  /// rules, the proxy path), from the HIP's value when the short way read it.
  void tick_general(const FieldView& field, const Vec3& hip, double voxel, double elapsed, bool edited,
                    bool covered_free_vhip, bool have_f_hip, double f_hip, TickOut& out);
  /// The common robust ticks (contact with no update due, free motion outside), the same
  /// bits as the general path; false (nothing changed but the HIP's value, read in free
  /// motion) where the general path must run. Not for edit ticks nor the tool.
  bool short_tick(const FieldView& field, const Vec3& hip, double voxel, double elapsed, bool& have_f_hip,
                  double& f_hip, TickOut& out);
  /// The robust tick: from the plain state (plain_state()) its prologue's arithmetic for
  /// that state, then the contact tick with no update due or the free tick outside on a
  /// short step, each point computed once (the free tick's read and the force limit out of
  /// line: free_read_tick, quick_contact_limited); else the tick_general that must run
  /// (general_tick), and where the full path must run (another state, a fault, an absurd
  /// HIP, a jump, a new snapshot version) tick_robust_full, nothing changed before.
  HriTick quick_tick(const FieldView& field, const Vec3& hip, double dt_s);
  /// finish_robust's state after a quick contact tick: proxy `to`, ramp target `target`,
  /// force sent `sent`, |F| sent `mag`.
  void quick_contact_state(const Vec3& hip, const Vec3& to, const Vec3& target, const Vec3& sent, double mag);
  /// finish_robust's state after a quick free tick (the HIP's value if it was read).
  void quick_free_state(const Vec3& hip, bool have_f_hip, double f_hip);
  /// quick_tick's contact tick where the force limit could act: |F| (mag) at or above
  /// force_limit_n, or not a number (limit_force: a fault, saturation).
  HriTick quick_contact_limited(const Vec3& hip, const Vec3& to, double g, Vec3 force, double mag);
  /// quick_tick's free tick that reads the HIP's value (not in the outside cell of the last
  /// read); tick_general where the general path must run (an entry, a long step).
  HriTick free_read_tick(const FieldView& field, const Vec3& hip, double voxel, double dt, bool in_cell);
  /// tick_general after a quick tick handed over, and its HriTick.
  HriTick general_tick(const FieldView& field, const Vec3& hip, double voxel, double elapsed, bool have_f_hip,
                       double f_hip);
  /// The state quick_tick covers: a configuration it covers (quick_ok_: the robust variant,
  /// the short way, a point tool, no force shading nor friction, a finite reach^2), started,
  /// no fault, restart, edit, ramp, release nor ease running, the snapshot version known
  /// where edits are tracked.
  bool plain_state() const;
  /// The configuration quick_tick covers, from params_ (quick_ok_).
  bool quick_covered() const;
  /// v_filt_ from the HIP and the time since the last sane tick [s] (prev_hip_ valid).
  void filter_velocity(const Vec3& hip, double elapsed);
  /// The fault (non-finite |F|) and saturation rules of a robust tick's force.
  void limit_force(Vec3& force, double& mag, TickOut& out) const;
  /// The robust tick's every tick: faults, restarts, edits, the tool, the short way, tick_general;
  /// plain_ set for the next tick.
  HriTick tick_robust_full(const FieldView& field, const Vec3& hip, double dt_s);
  /// tick_robust_full's tick.
  HriTick tick_robust_full_body(const FieldView& field, const Vec3& hip, double dt_s);
  /// The end of a robust tick: saturation, the edit ease, the state for the next tick.
  void finish_robust(const Vec3& hip, Vec3 force, bool edited, bool have_f_hip, double f_hip, TickOut& out);
  /// Contact force and VHIP for a HIP behind the plane (shared by both variants).
  Vec3 contact_force(const FieldView& field, const Vec3& hip, const Vec3& v_device, double dt,
                     TickOut& out);
  /// Edits: record the snapshot version of a sane tick; true if it differs from the last.
  bool note_version(std::uint64_t version);
  /// A new snapshot changed samples this renderer reads (its FieldView::changed box within
  /// reach of the HIP, the VHIP or the tool's scan); unknown boxes always reach.
  bool edit_reaches(const FieldView& field, const Vec3& hip) const;
  /// Edits: adds the edit ease's offset (what is left of it after this tick) to `force`, the
  /// target (|F| = mag [N], after saturation), saturated again; returns the |F| sent [N]. Sets
  /// out.contact, out.penetration_m and eased_vhip_ while the offset pushes.
  double edit_ease(const Vec3& hip, Vec3& force, double mag, TickOut& out);
  /// Spherical tool: rebuild the planes from the proxy of the tick before toward `hip`.
  void tool_rebuild(const FieldView& field, const Vec3& hip);
  /// Spherical tool: the planes from Newton searches (tools too large for surface_scan).
  void tool_rebuild_newton(const FieldView& field, const Vec3& hip);
  /// Spherical tool: fills scan_ with the surface points of the cells within `reach` of x
  /// (nearest first) and scan_clear_m_ with the nearest one's distance (reach if none);
  /// false if the box of cells exceeds kScanSide samples per axis (nothing scanned).
  bool surface_scan(const FieldView& field, const Vec3& x, double reach);
  /// Spherical tool: adds a plane for every scanned point within `reach` of x in front of
  /// every held plane (nearest first); returns the number added.
  int tool_add_uncovered(const Vec3& x, double reach, double voxel);
  /// Spherical tool, thin features (see the class docs): at an update whose proxy `solved`
  /// turned more than kEntryConeDeg from entry_n_ (or is the HIP) while the sphere at the HIP
  /// overlaps the material, holds the entry side (the planes of the tick before, `kept`, that
  /// face it, and the new ones that do not face away; `solved` their proxy) where the HIP is
  /// past the middle of the feature, or was found past it since; else entry_n_ follows.
  /// holding: a contact went on from the tick before (else entry_n_ is the new contact's).
  void tool_hold_entry_side(const FieldView& field, const Vec3& hip, bool holding, const ToolPlane* kept,
                            int kept_count, Vec3& solved);
  /// Spherical tool: the sphere at `hip` overlaps the material (the HIP inside, or the
  /// nearest surface point within r); m: a point inside (have_m), the HIP or just behind that
  /// point. Scans the cells within r of the HIP (surface_scan), else searches (nearest_surface).
  bool tool_near_material(const FieldView& field, const Vec3& hip, double voxel, Vec3& m, bool& have_m);
  /// Spherical tool: from m (inside), the material ends both ways along n within `reach` [m]
  /// and the HIP's level along n is at or past the middle of that chord (less half of a
  /// quarter voxel): the tool is past the middle of a thin feature.
  bool tool_past_middle(const FieldView& field, const Vec3& m, const Vec3& hip, const Vec3& n, double reach,
                        double voxel) const;
  /// The thin-feature marches (past_middle, tool_past_middle): fifth-voxel steps over
  /// `reach` [m], at least 2 and at most march_budget / 2.
  int chord_steps(double reach, double voxel) const;
  /// Along segments a and b at once, `steps` equal steps: the first step on each where the
  /// material ends (a_out, b_out; left 0 where it does not, so pass them as 0).
  void material_ends(FieldView::Segment& a, FieldView::Segment& b, int steps, int& a_out, int& b_out) const;
  /// Spherical tool: this tick's force (before saturation); sets out.contact, vhip_.
  Vec3 tool_tick(const FieldView& field, const Vec3& hip, bool edited, TickOut& out);
  /// The segment a -> b is longer than half a voxel (worth searching for a crossing).
  static bool long_step(const FieldView& field, const Vec3& a, const Vec3& b);

  HriParams params_;
  VirtualPlane plane_;
  Vec3 vhip_;
  Vec3 prev_hip_;
  double prev_force_mag_ = 0;
  int c_ = 0;
  int recovery_ticks_left_ = 0;  ///< paper: ticks left in the recovery ramp
  int recovery_ticks_ = 0;       ///< paper: ramp length [ticks] at the nominal period
  double ramp_left_s_ = 0;       ///< robust: time left in the recovery ramp [s]
  double ramp_dt_s_ = 1e-3;      ///< robust: this tick's period for the ramp, <= 2/rate [s]
  bool after_fault_ = false;     ///< robust: the tick before was a fault (force was 0)
  double recovery_from_n_ = 0;  ///< paper: ramp start [N]; robust: offset to fade out [N]
  bool started_ = false;
  bool quick_ok_ = false;  ///< the configuration quick_tick covers (set in the constructor)
  bool plain_ = false;     ///< plain_state() after the last tick of a path that can change it
  bool resync_ = false;
  bool sliding_ = false;
  bool was_contact_ = false;
  // Robust variant only:
  mutable double last_grad_norm_ = 0;  ///< |grad| measured by the last plane_at
  double plane_grad_norm_ = 0;         ///< |grad| where the held plane was made
  double dt_nominal_s_ = 1e-3;  ///< 1 / rate_hz [s]
  double inv_wpd_ = 1.0;        ///< 1 / world_per_device
  double alpha_nominal_ = 1.0;  ///< low-pass alpha at the nominal period
  Vec3 anchor_;            ///< VHIP where the plane was last computed (world [m])
  Vec3 v_filt_;            ///< filtered HIP velocity, device [m/s]
  bool vel_valid_ = false; ///< prev_hip_ is a sane HIP of the tick before
  double lost_s_ = 0;      ///< time spent in faults since the last sane tick [s]
  double vhip_value_ = 0;  ///< field value at vhip_ when vhip_value_known_
  bool vhip_value_known_ = false;
  bool vhip_outside_ = false;  ///< free VHIP in an outside cell of this snapshot (its value not read)
  // Robust variant, free motion (quick_tick): the cell of the last free tick's read. Every
  // corner of an outside cell is outside, so no point in it is inside (the trilinear value
  // is a blend of the corners): a free HIP that stays in it needs no read. Cleared by the
  // general path (an entry, a long step, every update and the end of every contact) and the
  // full path (a new version, a fault, a restart), so while it is set every tick since its
  // read was a free tick in it: the VHIP is in it too. It holds for one snapshot (storage and
  // version): a snapshot's samples and grid never change under its version (an edit
  // publishes the next one), which the VHIP's cached value relies on as well.
  bool cell_valid_ = false;
  bool cell_outside_ = false;
  const void* cell_storage_ = nullptr;  ///< FieldView::storage of the cell's snapshot
  Vec3 cell_lo_m_, cell_hi_m_;          ///< the cell's box (FieldView::cell_range) [m]
  std::uint64_t reads_skipped_ = 0;     ///< free ticks that read no sample (an outside cell)
  // Robust variant, edits (see the class docs, "Edits"):
  std::uint64_t field_version_ = 0;  ///< FieldView::version read by the last sane tick
  bool version_known_ = false;       ///< field_version_ holds a version
  VirtualPlane ramp_ref_;  ///< the plane before this tick's update (tick_general), for the ramp's trigger
  bool version_skipped_ = false;     ///< the last new version was not field_version_ + 1 (edit_reaches: reached)
  bool edit_tick_ = false;           ///< this tick reads a new version (no recovery ramp starts)
  bool edit_easing_ = false;         ///< an edit ease runs (edit_ease_left_s_ > 0)
  double edit_ease_left_s_ = 0;      ///< time left in the edit ease [s]
  Vec3 edit_ease_from_;              ///< the ease's offset E at its start [N]
  Vec3 eased_vhip_;                  ///< the proxy shown on an eased tick (world [m])
  bool show_eased_vhip_ = false;     ///< this tick shows eased_vhip_
  double edit_ease_max_rate_ = 0;    ///< largest |E| / edit_period_s of an ease so far [N/s]
  std::uint64_t edit_eased_ticks_ = 0;    ///< ticks whose force the edit ease changed
  std::uint64_t release_fade_ticks_ = 0;  ///< ticks of a release fade (recovery_time_s)
  Vec3 prev_force_;                  ///< force sent the tick before, device axes [N]
  Vec3 prev_target_f_;               ///< robust: unramped force of the tick before [N]
  Vec3 ramp_from_dir_;               ///< robust: unit direction sent when the ramp started (0: none)
  double release_left_s_ = 0;        ///< robust: time left in a release fade [s]
  Vec3 release_from_;                ///< robust: force sent on the last contact tick [N]
  Vec3 entry_n_;                     ///< robust: the normal the contact entered with (hold_entry_side)
  bool entry_held_ = false;          ///< robust: the HIP was found past a thin feature's middle (hold_entry_side)
  Vec3 entry_hip_;                   ///< robust: the HIP when entry_n_ was set [m] (hold_entry_side)
  Vec3 entry_vhip_;                  ///< robust: the VHIP when entry_n_ was set [m] (hold_entry_side)
  Vec3 entry_proxy_;                 ///< robust: the proxy the plane gave the HIP when entry_n_ was set [m] (hold_entry_side)
  Vec3 entry_deep_hip_;              ///< robust: the deepest HIP along entry_n_ at an update since it was set [m]
  double entry_deep_depth_ = 0;      ///< robust: that HIP's depth behind the plane held then [m] (hold_entry_side)
  // Spherical tool:
 public:
  static constexpr double kEntryConeDeg = 20.0;  ///< thin features: the turn from entry_n_ checked [deg]
  static constexpr int kMaxToolPlanes = 6;  ///< planes held at once (a bed of blobs needs more than 3)
  static constexpr int kScanSide = 20;      ///< samples per axis surface_scan reads at most
  static constexpr int kMaxScanPoints = 96; ///< surface points surface_scan keeps (the nearest)

 private:
  struct ScanPoint {
    Vec3 q;      ///< on the isosurface [m]
    Vec3 n;      ///< outward normal of the plane it makes
    double d;    ///< distance from the scan centre [m]
  };
  ToolPlane tool_planes_[kMaxToolPlanes];
  int tool_plane_count_ = 0;
  ScanPoint scan_[kMaxScanPoints];
  int scan_count_ = 0;
  double scan_clear_m_ = 0;     ///< distance of the nearest surface point of the last scan [m]
  bool tool_reseat_ = false;    ///< set_tool_radius(): the next tool tick rebuilds its planes
  bool scan_valid_ = false;     ///< anchor_ is the centre of a complete scan of the field version
  float scan_excess_[kScanSide * kScanSide * kScanSide];
};

}  // namespace isotouch::servo
