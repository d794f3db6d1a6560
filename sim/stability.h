// stability.h - stiff walls, passivity and extreme inputs: measured, not assumed.
#pragma once
#include "isotouch/sim/servo_names.h"
#include <string>
#include <vector>

#include "isotouch/servo/hri.h"
#include "isotouch/core/sample_field.h"
#include "isotouch/sim/sim_device.h"

namespace isotouch::sim {

/// A held contact: the device comes in at approach speed, the operator's hand (a weak
/// spring, little damping) keeps pushing it into the surface with push_force_n.
struct HeldContact {
  double period_s = 1e-3;                ///< servo period T [s]
  double stiffness_n_per_m = 1000;       ///< K [N/m]
  double virtual_damping_n_s_per_m = 0;  ///< B [N s/m] (HRI eq. 3)
  int plane_update_period = 1;           ///< n
  SimDeviceParams device = [] {
    SimDeviceParams d;
    d.damping_n_s_per_m = 1.0;           // b
    d.hand_stiffness_n_per_m = 50;
    d.hand_damping_n_s_per_m = 0;        // "little operator damping"
    d.force_max_n = 1e3;                 // no saturation: the linear theory
    d.substeps = 40;
    return d;
  }();
  double push_force_n = 1.0;             ///< hand pre-load into the surface [N]
  double approach_speed_m_s = 0.05;      ///< speed at first contact [m/s]
  double duration_s = 3.0;
  bool passivity_controller = false;     ///< Hannaford-Ryu controller on the port
  /// Largest damping the passivity controller adds. Keep it below ~m/T: a sampled
  /// damper alpha with alpha T / m > 2 is itself unstable.
  double pc_alpha_max_n_s_per_m = 50;
};

struct HeldContactResult {
  bool sustained_oscillation = false;  ///< late oscillation energy > 0.5 x early
  bool gains_energy = false;           ///< the display handed out more than tolerance_j
  bool nonfinite = false;              ///< any NaN/Inf force or position
  double early_energy_j = 0;           ///< mean oscillation energy in [0.2, 0.45] of the run
  double late_energy_j = 0;            ///< ... in [0.75, 1.0]
  double energy_out_j = 0;             ///< max over t of (rendered work - device damping loss)
  double tolerance_j = 0;              ///< 1 % of the wall's stored energy at equilibrium
  double max_force_n = 0;
  long ticks = 0, contact_ticks = 0;
  /// Deepest the device (HIP) went behind the surface plane through surface_point [m].
  double max_hip_depth_m = 0;
  /// Largest |N . (VHIP - surface_point)| over the contact ticks [m] (0 on the wall: the
  /// contact point stays on the surface).
  double max_vhip_off_surface_m = 0;
  /// Ticks after the first contact where the HIP was more than 1 um behind the surface
  /// plane but no contact or a zero force was rendered (the contact was not held).
  long inside_without_contact_ticks = 0;
  bool stable() const { return !sustained_oscillation && !gains_energy && !nonfinite; }
};

/// Simulate a held contact against `field`'s isosurface tau = 0 (inside above) at
/// `surface_point` with outward `normal` (world = device frame [m]).
HeldContactResult simulate_held_contact(const SampleField& field, const Vec3& surface_point,
                                        const Vec3& normal, const HeldContact& cfg);

/// Colgate and Schenkel's passivity bound K_max = 2 (b - |B|) / T [N/m].
inline double colgate_k_max(double b, double B, double T) { return 2.0 * (b - (B < 0 ? -B : B)) / T; }

/// Largest K in [k_lo, k_hi] (log bisection) with a stable held contact.
/// Returns k_lo if even k_lo is unstable, k_hi if k_hi is still stable.
double find_k_max(const SampleField& field, const Vec3& surface_point, const Vec3& normal,
                  HeldContact cfg, double k_lo, double k_hi, int iterations = 16);

/// One extreme case: what was done, what had to hold, whether it held, and figures.
struct ExtremeCase {
  std::string name;
  std::string expectation;
  bool passed = false;
  std::string detail;
};

/// Every extreme case (K = 1e5, 5 cm jump across a thin shell, start deep inside,
/// leave/re-enter, NaN/Inf/huge device input, zero gradient, HIP outside the volume, NaN
/// voxels, isovalue at the data min/max, n = 1 and 1000, force above the device limit).
std::vector<ExtremeCase> run_extreme_cases();
int extreme_case_count();
/// Case i of run_extreme_cases(), 0 <= i < extreme_case_count().
ExtremeCase run_extreme_case(int i);

/// `ticks` random ticks over random fields, parameters and HIPs (with NaN, Inf, huge
/// values and long jumps mixed in), no friction, shading or recovery. Returns the number
/// of ticks that broke a property (must be 0) and fills max_force_ratio (max |F| / F_max).
/// Properties: force and VHIP finite; |F| <= F_max; zero force on every tick without
/// contact; in contact, F along the plane normal N (|F - (F.N) N| <= 1e-9 |F|), pushing
/// (F.N >= 0), and the VHIP on the plane (|N . (VHIP - p)| <= 1e-9 m); a fault tick has
/// zero force. `detail`, if given, receives the count per property.
long random_tick_property(long ticks, unsigned seed, double& max_force_ratio, std::string* detail = nullptr);

}  // namespace isotouch::sim
