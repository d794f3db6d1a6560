#include "isotouch/io/scene_servo.h"

#include <cmath>
#include <iomanip>
#include <sstream>

namespace isotouch::io {
namespace {

const char* variant_name(servo::Variant v) { return v == servo::Variant::kPaper ? "paper" : "robust"; }

const char* intersection_name(servo::Intersection i) {
  switch (i) {
    case servo::Intersection::kSecant: return "secant";
    case servo::Intersection::kBisection: return "bisection";
    default: return "linear";
  }
}

const char* normal_name(servo::NormalSource n) {
  switch (n) {
    case servo::NormalSource::kCentral: return "central";
    case servo::NormalSource::kTrilinearExact: return "exact";
    default: return "samples";
  }
}

/// The tool's radius in millimetres that the parser's 1e-3 * mm turns back into `r_m` exactly
/// (r_m * 1e3 alone does not for some radii: 4.5 mm), or the nearest there is.
double radius_mm(double r_m) {
  double mm = r_m * 1e3;
  for (int i = 0; i < 8 && 1e-3 * mm != r_m; ++i) mm = std::nextafter(mm, 1e-3 * mm < r_m ? INFINITY : -INFINITY);
  return mm;
}

}  // namespace

std::string servo_section_json(const servo::HriParams& h) {
  std::ostringstream j;
  j << std::setprecision(17) << "{\"variant\": \"" << variant_name(h.variant) << "\", \"stiffness_n_per_m\": "
    << h.stiffness_n_per_m << ", \"damping_n_s_per_m\": " << h.damping_n_s_per_m
    << ", \"plane_update_period\": " << h.plane_update_period << ", \"rate_hz\": " << h.rate_hz
    << ", \"force_limit_n\": " << h.force_limit_n;
  // The paper variant refuses other rules even when they are its own: written only for robust.
  if (h.variant == servo::Variant::kRobust)
    j << ", \"intersection\": \"" << intersection_name(h.intersection) << "\", \"normal\": \"" << normal_name(h.normal)
      << "\"";
  j << ", \"intersection_steps\": " << h.intersection_steps << ", \"force_shading\": "
    << (h.force_shading ? "true" : "false") << ", \"recovery_time_s\": " << h.recovery_time_s;
  if (h.friction.any())
    j << ", \"friction\": {\"mu_s\": " << h.friction.mu_s << ", \"mu_d\": " << h.friction.mu_d
      << ", \"viscous_n_s_per_m\": " << h.friction.viscous_n_s_per_m << "}";
  if (h.tool_radius_m > 0) j << ", \"tool\": {\"radius_mm\": " << radius_mm(h.tool_radius_m) << "}";
  j << "}";
  return j.str();
}

std::string unrecordable_field(const servo::HriParams& w, const servo::HriParams& p) {
  std::ostringstream o;
  o << std::setprecision(17);
  auto differs = [&](const char* name, auto a, auto b) {
    if (o.tellp() > 0 || a == b) return;
    o << name << ' ' << +a;
  };
  differs("tau", w.tau, p.tau);
  differs("inside", int(w.inside), int(p.inside));
  differs("variant", int(w.variant), int(p.variant));
  differs("stiffness_n_per_m", w.stiffness_n_per_m, p.stiffness_n_per_m);
  differs("damping_n_s_per_m", w.damping_n_s_per_m, p.damping_n_s_per_m);
  differs("plane_update_period", w.plane_update_period, p.plane_update_period);
  differs("rate_hz", w.rate_hz, p.rate_hz);
  differs("force_limit_n", w.force_limit_n, p.force_limit_n);
  differs("max_reach_m", w.max_reach_m, p.max_reach_m);
  if (w.variant == servo::Variant::kRobust) {  // the paper variant renders linear and central whatever they say
    differs("intersection", int(w.intersection), int(p.intersection));
    differs("normal", int(w.normal), int(p.normal));
  }
  differs("intersection_steps", w.intersection_steps, p.intersection_steps);
  differs("friction.mu_s", w.friction.mu_s, p.friction.mu_s);
  differs("friction.mu_d", w.friction.mu_d, p.friction.mu_d);
  differs("friction.viscous_n_s_per_m", w.friction.viscous_n_s_per_m, p.friction.viscous_n_s_per_m);
  differs("force_shading", w.force_shading, p.force_shading);
  differs("recovery_time_s", w.recovery_time_s, p.recovery_time_s);
  differs("velocity_cutoff_hz", w.velocity_cutoff_hz, p.velocity_cutoff_hz);
  differs("max_speed_m_s", w.max_speed_m_s, p.max_speed_m_s);
  differs("march_budget", w.march_budget, p.march_budget);
  differs("edit_period_s", w.edit_period_s, p.edit_period_s);
  differs("tool_radius_m", w.tool_radius_m, p.tool_radius_m);
  differs("short_way", w.short_way, p.short_way);
  return o.str();
}

}  // namespace isotouch::io
