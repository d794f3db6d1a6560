#include "isotouch/sim/linked_contact.h"

#include <algorithm>
#include <cmath>

#include "isotouch/core/setting_check.h"
#include "isotouch/sim/analytic_fields.h"
#include "isotouch/servo/port_passivity.h"

namespace isotouch::sim {
namespace {

const Vec3 kLinkWallPoint{0.016, 0.016, 0.010}, kLinkWallNormal{0, 0, 1};  // the link sweep's wall

struct PoseMessage {
  Vec3 x;              ///< device position [m]
  double sent_s = 0;   ///< device time it was sent [s]
};
struct ForceMessage {
  Vec3 f;                  ///< force the servo rendered [N]
  double pose_sent_s = 0;  ///< when the pose it answers was sent [s]
};

/// The servo end: one HRI tick on each pose received.
class ServoEnd {
 public:
  explicit ServoEnd(const LinkedContact& cfg) : renderer_(params(cfg)) {}
  ForceMessage render(const SampleField& field, const PoseMessage& p) {
    return {renderer_.tick(field, p.x).force_n, p.sent_s};
  }

 private:
  static HriParams params(const LinkedContact& cfg) {
    HriParams hp;
    hp.tau = 0;
    hp.stiffness_n_per_m = cfg.stiffness_n_per_m;
    hp.damping_n_s_per_m = cfg.servo_damping_n_s_per_m;
    hp.plane_update_period = 1;
    hp.rate_hz = cfg.link.rate_hz;
    hp.force_limit_n = cfg.device.force_max_n;
    return hp;
  }
  HriRenderer renderer_;
};

/// The device ticks per link message [1]; throws unless the timing can be honoured: a
/// finite positive device period and a link period that is a whole number of them (the
/// servo is told the link's rate; a rounded one would be another rate).
long device_ticks_per_message(const LinkedContact& cfg) {
  cfg.link.validate();
  core::require_positive("LinkedContact", "device_period_s", cfg.device_period_s, "s");
  core::require_positive("LinkedContact", "duration_s", cfg.duration_s, "s");
  const double ticks = cfg.link.period_s() / cfg.device_period_s;
  const double whole = std::round(ticks);
  core::require_setting(whole >= 1 && std::abs(ticks - whole) <= 1e-9 * whole, "LinkedContact", "link.rate_hz",
                        cfg.link.rate_hz, "its period must be a whole number (>= 1) of device_period_s");
  return long(whole);
}

/// Where the hand pulls the device at time t [s].
Vec3 hand_target(const LinkedContact& cfg, const Vec3& p0, const Vec3& n, double t) {
  if (cfg.motion == LinkedMotion::kPress) return p0 - n * (cfg.push_force_n / cfg.device.hand_stiffness_n_per_m);
  const double s = std::min(cfg.press_depth_m, cfg.press_speed_m_s * t - 1e-3);
  return p0 - n * s;
}

Vec3 hand_target_velocity(const LinkedContact& cfg, const Vec3& n, double t) {
  if (cfg.motion == LinkedMotion::kPress || cfg.press_speed_m_s * t - 1e-3 >= cfg.press_depth_m) return {};
  return n * -cfg.press_speed_m_s;
}

void record_round_trip(LinkedContactResult& r, double s) {
  r.round_trip_min_s = r.round_trips == 0 ? s : std::min(r.round_trip_min_s, s);
  r.round_trip_max_s = std::max(r.round_trip_max_s, s);
  ++r.round_trips;
}

/// Half the peak-to-peak of s over [from, to) (to clipped at the end).
double half_span(const std::vector<double>& s, std::size_t from, std::size_t to) {
  to = std::min(to, s.size());
  if (from >= to) return 0;
  const auto [lo, hi] = std::minmax_element(s.begin() + long(from), s.begin() + long(to));
  return 0.5 * (*hi - *lo);
}

/// Largest |sum F / (K sum depth) - 1| over windows of `w` ticks with mean depth > 1 mm.
double windowed_stiffness_error(const std::vector<double>& force, const std::vector<double>& height, double k, long w) {
  double worst = 0;
  for (std::size_t a = 0; a + std::size_t(w) <= force.size(); a += std::size_t(w)) {
    double f = 0, d = 0;
    for (std::size_t i = a; i < a + std::size_t(w); ++i) f += force[i], d -= height[i];
    if (d / double(w) > 1e-3) worst = std::max(worst, std::abs(f / (k * d) - 1));
  }
  return worst;
}

/// The figures of the device's motion, from its height above the wall at each tick [m].
void judge_motion(LinkedContactResult& r, const std::vector<double>& height, const LinkedContact& cfg, double T) {
  const std::size_t n = height.size(), never = n;
  const std::size_t settled = r.contact_time_s < 0 ? never : std::size_t(std::ceil((r.contact_time_s + 0.2) / T));
  r.settled_amplitude_m = half_span(height, settled, n);
  r.early_amplitude_m = half_span(height, std::size_t(0.2 * double(n)), std::size_t(0.45 * double(n)));
  r.late_amplitude_m = half_span(height, n - n / 4, n);
  if (cfg.motion == LinkedMotion::kSlowPress)
    r.max_force_error_ratio = windowed_stiffness_error(r.force_trace_n, height, cfg.stiffness_n_per_m, long(0.1 / T));
}

}  // namespace

LinkedContactResult simulate_linked_contact(const SampleField& field, const Vec3& p0, const Vec3& normal,
                                            const LinkedContact& cfg) {
  const Vec3 n = normalized_or(normal, {0, 0, 1});
  const double T = cfg.device_period_s;
  const long link_every = device_ticks_per_message(cfg);
  DelayLine<PoseMessage> up(cfg.link, 0);
  DelayLine<ForceMessage> down(cfg.link, 1);
  ServoEnd servo(cfg);
  servo::PortPassivity pc(cfg.passivity_controller, cfg.pc_alpha_max(), cfg.device.force_max_n);
  const bool press = cfg.motion == LinkedMotion::kPress;
  SimDevice dev(cfg.device, press ? p0 + n * 2e-4 : p0 + n * 1e-3);
  if (press) dev.set_state(p0 + n * 2e-4, n * -cfg.approach_speed_m_s);

  LinkedContactResult r;
  r.ticks = long(std::ceil(cfg.duration_s / T));
  r.force_trace_n.reserve(std::size_t(r.ticks));
  std::vector<double> height(std::size_t(r.ticks));
  PoseMessage pose_in{};
  ForceMessage force_held{};
  for (long k = 0; k < r.ticks; ++k) {
    const double t = double(k) * T;
    const Vec3 x = dev.position();
    if (k % link_every == 0) up.send(t, {x, t});
    if (up.receive(t, pose_in) > 0) down.send(t, servo.render(field, pose_in));
    if (down.receive(t, force_held) > 0) record_round_trip(r, t - force_held.pose_sent_s);
    const Vec3 f = pc.step(t, x, force_held.f);
    dev.command_force(f);
    dev.step(T, hand_target(cfg, p0, n, t), hand_target_velocity(cfg, n, t));
    if (!finite(f) || !finite(dev.true_position())) r.nonfinite = true;
    const double fn = dot(dev.applied_force(), n);
    const double depth = -dot(dev.true_position() - p0, n);
    r.force_trace_n.push_back(fn);
    r.max_force_n = std::max(r.max_force_n, std::abs(fn));
    if (r.contact_time_s < 0 && fn > 0) r.contact_time_s = t;
    if (!press && depth > 1e-3)
      r.max_tick_force_error_ratio = std::max(r.max_tick_force_error_ratio,
                                              std::abs(fn - cfg.stiffness_n_per_m * depth) / (cfg.stiffness_n_per_m * depth));
    height[std::size_t(k)] = dot(dev.true_position() - p0, n);
    r.device_energy_out_j = std::max(r.device_energy_out_j, dev.rendered_work_j() - dev.damping_dissipated_j());
  }
  judge_motion(r, height, cfg, T);
  r.pc_energy_in_j = pc.energy_in_j();
  r.pc_energy_out_j = pc.energy_out_j();
  r.pc_dissipated_j = pc.dissipated_j();
  r.pc_active_ticks = pc.active_ticks();
  return r;
}

bool LinkedContactResult::stable(const LinkedContact& cfg) const {
  const double k = cfg.stiffness_n_per_m;
  const double d_eq = cfg.push_force_n / (k + cfg.device.hand_stiffness_n_per_m);
  const double tolerance_j = kEnergyTolerance * 0.5 * k * d_eq * d_eq;
  const bool sustained = late_amplitude_m > kStillAmplitudeM && late_amplitude_m > kDecayRatio * early_amplitude_m;
  return !nonfinite && !sustained && device_energy_out_j <= tolerance_j;
}

double find_k_max_linked(const SampleField& field, const Vec3& p0, const Vec3& normal, LinkedContact cfg,
                         double lo, double hi, int iterations) {
  auto stable = [&](double k) {
    cfg.stiffness_n_per_m = k;
    return simulate_linked_contact(field, p0, normal, cfg).stable(cfg);
  };
  if (!stable(lo)) return 0;
  if (stable(hi)) return hi;
  for (int i = 0; i < iterations; ++i) {
    const double mid = std::sqrt(lo * hi);
    (stable(mid) ? lo : hi) = mid;
  }
  return lo;
}

LinkBound link_k_max(LinkedContact base, double rate_hz, double round_trip_s, int iterations) {
  core::require_positive("link_k_max", "rate_hz", rate_hz, "Hz");
  core::require_non_negative("link_k_max", "round_trip_s", round_trip_s, "s");
  const double period = 1.0 / rate_hz;
  // base's own device loop where the link's period is a whole number of it (the sweep's
  // rates), else the whole number of ticks nearest 1 ms.
  const double as_is = period / base.device_period_s;
  if (!(std::round(as_is) >= 1 && std::abs(as_is - std::round(as_is)) <= 1e-9 * std::round(as_is)))
    base.device_period_s = period / std::max(1.0, std::round(period / 1e-3));
  base.link.rate_hz = rate_hz;
  base.link.round_trip_delay_s = round_trip_s;
  base.motion = LinkedMotion::kPress;
  const SampleField wall = plane_field(kLinkWallNormal, kLinkWallPoint);
  LinkBound b;
  b.rate_hz = rate_hz;
  b.round_trip_s = round_trip_s;
  b.device_period_s = base.device_period_s;
  for (bool pc : {false, true}) {
    base.passivity_controller = pc;
    (pc ? b.k_max_with_pc_n_per_m : b.k_max_n_per_m) = find_k_max_linked(
        wall, kLinkWallPoint, kLinkWallNormal, base, kLinkSearchLoNPerM, kLinkSearchHiNPerM, iterations);
  }
  return b;
}

}  // namespace isotouch::sim
