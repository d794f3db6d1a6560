#include "isotouch/service/transform_device.h"

namespace isotouch::service {

void TransformDevice::set_frame(const engine::Volume& v, const core::Vec3& offset_mm) {
  frame_.grid = v.grid;
  frame_.direction = v.direction;
  frame_.direction_is_identity = v.direction_is_identity;
  offset_mm_ = offset_mm;
}

void TransformDevice::push_mm(const double t_mm[3], std::uint64_t stamp) {
  std::lock_guard<std::mutex> lock(push_mu_);  // one writer at a time (any client's thread)
  Pose p = pose_.load();
  for (int a = 0; a < 3; ++a) p.mm[a] = t_mm[a];
  p.received_ns = now_ns();  // steady_clock is CLOCK_MONOTONIC, the servo's clock
  p.stamp = stamp;
  ++p.sequence;
  pose_.store(p);
  pushed_.fetch_add(1);
}

TransformDevice::PoseId TransformDevice::newest_pose() const {
  const Pose p = pose_.load();
  return {p.sequence, p.received_ns, p.stamp};
}

servo::DeviceReading TransformDevice::read() {
  pose_.load(last_);  // bounded: keeps the last pose if a store stays in progress
  const Pose& p = last_;
  servo::DeviceReading r;
  // RAS mm + offset -> LPS m -> grid m.
  const core::Vec3 lps{-(p.mm[0] + offset_mm_.x) * 1e-3, -(p.mm[1] + offset_mm_.y) * 1e-3, (p.mm[2] + offset_mm_.z) * 1e-3};
  r.position_m = frame_.to_grid(lps);
  // Nothing yet: an arrival long ago, so the servo judges it stale (zero force).
  r.received_ns = p.received_ns > 0 ? p.received_ns : 1;
  r.sequence = p.sequence;
  return r;
}

void TransformDevice::write_force_n(const core::Vec3& f) { force_.store({f, now_ns()}); }

core::Vec3 TransformDevice::force_ras_n(double stall_s) const {
  const Force f = force_.load();
  if (f.written_ns == 0 || double(now_ns() - f.written_ns) * 1e-9 > stall_s) return {0, 0, 0};
  const core::Vec3 lps = frame_.direction_apply(f.f);
  return {-lps.x, -lps.y, lps.z};
}

core::Vec3 TransformDevice::grid_to_ras_mm(const core::Vec3& g) const {
  const core::Vec3 p = frame_.to_physical(g);
  return {-p.x * 1e3, -p.y * 1e3, p.z * 1e3};
}

}  // namespace isotouch::service
