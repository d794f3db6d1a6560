#include "isotouch/service/transform_device.h"

namespace isotouch::service {

void TransformDevice::set_frame(const engine::Volume& v, const core::Vec3& offset_mm) {
  echo_.set_frame(v);
  offset_mm_ = offset_mm;
}

void TransformDevice::push_mm(const double t_mm[3], std::uint64_t stamp) {
  std::lock_guard<std::mutex> lock(push_mu_);  // one writer at a time (any client's thread)
  Pose p = pose_.load();
  const core::Vec3 image = reg_.to_image_mm({t_mm[0], t_mm[1], t_mm[2]});
  p.mm[0] = image.x, p.mm[1] = image.y, p.mm[2] = image.z;
  p.received_ns = now_ns();  // steady_clock is CLOCK_MONOTONIC, the servo's clock
  arrivals_.arrived(p.received_ns);
  p.stamp = stamp;
  ++p.sequence;
  pose_.store(p);
  pushed_.fetch_add(1);
}

void TransformDevice::set_registration(const Registration& r) {
  std::lock_guard<std::mutex> lock(push_mu_);
  reg_ = r;
  reg_cell_.store(r);
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
  r.position_m = echo_.frame().to_grid(lps);
  // Nothing yet: an arrival long ago, so the servo judges it stale (zero force).
  r.received_ns = p.received_ns > 0 ? p.received_ns : 1;
  r.sequence = p.sequence;
  return r;
}

}  // namespace isotouch::service
