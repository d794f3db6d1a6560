// linked_contact.h - a contact rendered through a delayed link: the servo (HRI) on one side,
// the simulated hand and device on the other, a DelayLine each way. The device end holds
// the last force received over its own loop (as PLUS and the vendor device threads do) and
// runs the time-domain passivity observer/controller there (servo/port_passivity.h), on the
// device's clock, with the one-port rule (the link and the wall behind it together never
// hand out more than they took in). Judged by the simulated device's own motion and energy, not by the
// controller's observer.
#pragma once
#include "isotouch/sim/servo_names.h"

#include <optional>
#include <vector>

#include "isotouch/core/sample_field.h"
#include "isotouch/sim/delayed_link.h"
#include "isotouch/sim/sim_device.h"

namespace isotouch::sim {

/// What the hand does: a press (comes in at approach speed and keeps pushing with
/// push_force_n) or a slow press (the hand target moves into the wall at press_speed).
enum class LinkedMotion { kPress, kSlowPress };

struct LinkedContact {
  LinkParams link;
  double device_period_s = 1e-3;        ///< the device end's loop [s]: holds the force, runs the controller
  double stiffness_n_per_m = 800;       ///< K of the wall [N/m]
  double servo_damping_n_s_per_m = 0;   ///< B: the servo's virtual damping (HRI eq. 3) [N s/m]
  LinkedMotion motion = LinkedMotion::kPress;
  SimDeviceParams device = [] {
    SimDeviceParams d;
    d.damping_n_s_per_m = 1.0;          // b: the Colgate bound at 1 kHz is 2000 N/m
    d.hand_stiffness_n_per_m = 50;      // a weak hand, little damping: the hard case
    d.hand_damping_n_s_per_m = 0;
    d.force_max_n = 1e3;                // no saturation: what the link does, not the motor
    d.substeps = 20;
    return d;
  }();
  double push_force_n = 1.0;            ///< press: hand pre-load into the wall [N]
  double approach_speed_m_s = 0.05;     ///< press: speed at first contact [m/s]
  double press_speed_m_s = 0.004;       ///< slow press: speed of the hand target [m/s]
  double press_depth_m = 0.008;         ///< slow press: the hand target stops this deep [m]
  double duration_s = 1.5;
  bool passivity_controller = false;
  /// Largest damping the controller adds [N s/m]; unset: pc_alpha_max() below.
  std::optional<double> pc_alpha_max_n_s_per_m;
  /// The damping cap in use [N s/m]: the one set, else 0.5 m / T_device from device.mass_kg
  /// and device_period_s (a sampled damper turns active at 2 m / T: a margin of 4).
  double pc_alpha_max() const {
    return pc_alpha_max_n_s_per_m ? *pc_alpha_max_n_s_per_m : 0.5 * device.mass_kg / device_period_s;
  }
};

struct LinkedContactResult {
  bool nonfinite = false;
  double contact_time_s = -1;           ///< first device tick with a force [s]
  /// Half the peak-to-peak of the device's position along the normal from 200 ms after
  /// contact to the end [m] (true position, device clock).
  double settled_amplitude_m = 0;
  /// The same over [0.2, 0.45] and over [0.75, 1] of the run [m].
  double early_amplitude_m = 0;
  double late_amplitude_m = 0;
  /// Largest work the applied force did on the device less the device's own viscous loss
  /// (device.damping_n_s_per_m): max over t [J]. > 0: the link's force did more work than
  /// the device's damper took out (not the link's own balance, which may be positive by up
  /// to that loss and still read <= 0 here).
  double device_energy_out_j = 0;
  double max_force_n = 0;
  /// Slow press: largest |mean F.N / (K mean depth) - 1| over 100 ms windows whose mean
  /// depth is over 1 mm: the stiffness the hand feels against K.
  double max_force_error_ratio = 0;
  /// Slow press: largest |F.N - K depth| / (K depth) over single ticks deeper than 1 mm
  /// (the ripple of a held force, and the controller's damping, included).
  double max_tick_force_error_ratio = 0;
  /// Normal force the device applied at each device tick [N] (for comparisons of runs).
  std::vector<double> force_trace_n;
  /// Time from a pose's sending to the device's receipt of the force rendered from it,
  /// over every force received [s] (the round trip as the simulation served it), and the
  /// number received.
  double round_trip_min_s = 0, round_trip_max_s = 0;
  long round_trips = 0;
  double pc_energy_in_j = 0, pc_energy_out_j = 0, pc_dissipated_j = 0;
  long pc_active_ticks = 0, ticks = 0;
  /// Stable: finite, no sustained oscillation (the late amplitude is under
  /// kStillAmplitudeM or under kDecayRatio of the early one) and device_energy_out_j at most
  /// kEnergyTolerance of the wall's stored energy at the press's equilibrium (K from cfg).
  bool stable(const LinkedContact& cfg) const;
  static constexpr double kStillAmplitudeM = 1e-6;  ///< [m]
  static constexpr double kDecayRatio = 0.5;        ///< late / early amplitude [1]
  static constexpr double kEnergyTolerance = 0.01;  ///< of 0.5 K d_eq^2 [1]
};

/// Simulate `cfg` against `field`'s isosurface tau = 0 (inside above) at `surface_point`,
/// outward `normal` (world = device frame [m]).
LinkedContactResult simulate_linked_contact(const SampleField& field, const Vec3& surface_point,
                                            const Vec3& normal, const LinkedContact& cfg);

/// Largest K in [k_lo, k_hi] (log bisection) whose press is stable through the link [N/m];
/// 0 when k_lo itself is unstable (K_max below the search).
double find_k_max_linked(const SampleField& field, const Vec3& surface_point, const Vec3& normal,
                         LinkedContact cfg, double k_lo, double k_hi, int iterations);

/// The stiffness bound of a wall through a link: the largest stable K of the press
/// `isotouch stability`'s link sweep runs (a flat wall, LinkedMotion::kPress, K searched by
/// find_k_max_linked over [kLinkSearchLoNPerM, kLinkSearchHiNPerM]) without and with the
/// device end's passivity controller [N/m]; 0 when even the search's floor is unstable.
struct LinkBound {
  double rate_hz = 0;            ///< the link rate simulated [Hz]
  double round_trip_s = 0;       ///< the round trip simulated [s]
  double device_period_s = 0;    ///< the device end's loop simulated [s] (a whole fraction of the link's period)
  double k_max_n_per_m = 0;      ///< without the controller [N/m]
  double k_max_with_pc_n_per_m = 0;  ///< with the device end's controller [N/m]
};
inline constexpr double kLinkSearchLoNPerM = 10, kLinkSearchHiNPerM = 1e5;
/// The bisection's steps in the link sweep (and at a link's open).
inline constexpr int kLinkSearchIterations = 10;

/// LinkBound for `base` (its device, hand, servo damping, press and duration; its K,
/// controller and link timing are set here) over a link at `rate_hz` with `round_trip_s`: the
/// device end's loop is base.device_period_s where the link's period is a whole number of it
/// (the sweep's rates), else the whole number of ticks per link period nearest 1 ms (at
/// least one), so that any measured rate is simulated as it is. Pure: the same arguments
/// give the same numbers. Each K's verdict is LinkedContactResult::stable (a stable K is
/// returned, never an unstable one: the bound errs low by at most one bisection step).
/// @throws std::invalid_argument naming the argument unless the rate is finite and > 0 and
/// the round trip finite and >= 0.
LinkBound link_k_max(LinkedContact base, double rate_hz, double round_trip_s,
                     int iterations = kLinkSearchIterations);

}  // namespace isotouch::sim
