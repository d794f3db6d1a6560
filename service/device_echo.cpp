#include "isotouch/service/device_echo.h"

namespace isotouch::service {

void RasEcho::set_frame(const engine::Volume& v) {
  frame_.grid = v.grid;
  frame_.direction = v.direction;
  frame_.direction_is_identity = v.direction_is_identity;
}

core::Vec3 RasEcho::force_ras_n(double stall_s) const {
  const Force f = force_.load();
  if (f.written_ns == 0 || double(now_ns() - f.written_ns) * 1e-9 > stall_s) return {0, 0, 0};
  return to_ras_n(f.f);
}

core::Vec3 RasEcho::to_ras_n(const core::Vec3& f) const {
  const core::Vec3 lps = frame_.direction_apply(f);
  return {-lps.x, -lps.y, lps.z};
}

core::Vec3 RasEcho::grid_to_ras_mm(const core::Vec3& g) const {
  const core::Vec3 p = frame_.to_physical(g);
  return {-p.x * 1e3, -p.y * 1e3, p.z * 1e3};
}

}  // namespace isotouch::service
