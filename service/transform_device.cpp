#include "isotouch/service/transform_device.h"

namespace isotouch::service {

void TransformDevice::set_frame(const engine::Volume& v, const core::Vec3& offset_mm) {
  echo_.set_frame(v);
  offset_mm_ = offset_mm;
}

void TransformDevice::push_mm(const double t_mm[3], std::uint64_t stamp) {
  std::lock_guard<std::mutex> lock(push_mu_);  // one writer at a time (any client's thread)
  Pose p = pose_.load();
  const std::int64_t now = now_ns();  // steady_clock is CLOCK_MONOTONIC, the servo's clock
  if (p.sequence != 0 && read_sequence_.load(std::memory_order_relaxed) < p.sequence) {  // p is never to be read
    constexpr std::int64_t kEdgesNs[kGapBins - 1] = {100'000, 300'000, 700'000, 1'300'000};
    const std::int64_t gap = now - p.received_ns;
    int bin = 0;
    while (bin < kGapBins - 1 && gap >= kEdgesNs[bin]) ++bin;
    overtaken_gaps_[std::size_t(bin)].fetch_add(1, std::memory_order_relaxed);
  }
  const core::Vec3 image = reg_.to_image_mm({t_mm[0], t_mm[1], t_mm[2]});
  p.mm[0] = image.x, p.mm[1] = image.y, p.mm[2] = image.z;
  p.received_ns = now;
  p.stamp = stamp;
  ++p.sequence;
  RecentSlot& slot = recent_[p.sequence % kRecent];  // before the pose: the reply thread looks it up once the servo read it
  slot.sequence.store(0, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  slot.received_ns.store(p.received_ns, std::memory_order_relaxed);
  slot.stamp.store(p.stamp, std::memory_order_relaxed);
  slot.sequence.store(p.sequence, std::memory_order_release);
  pose_.store(p);
  // The arrival announced after the pose is readable: a servo tick waiting for it
  // (ServoThread::wait_for_input) ends when the clock moves, and reads the pose then.
  arrivals_.arrived(p.received_ns);
  pushed_.fetch_add(1);
}

long TransformDevice::overtaken() const {
  long n = 0;
  for (long g : overtaken_gaps()) n += g;
  return n;
}

std::array<long, TransformDevice::kGapBins> TransformDevice::overtaken_gaps() const {
  std::array<long, kGapBins> g{};
  for (std::size_t i = 0; i < g.size(); ++i) g[i] = overtaken_gaps_[i].load(std::memory_order_relaxed);
  return g;
}

TransformDevice::PoseId TransformDevice::recent_pose(std::uint64_t sequence) const {
  const RecentSlot& slot = recent_[sequence % kRecent];
  if (sequence == 0 || slot.sequence.load(std::memory_order_acquire) != sequence) return {};
  const PoseId id{sequence, slot.received_ns.load(std::memory_order_relaxed), slot.stamp.load(std::memory_order_relaxed)};
  std::atomic_thread_fence(std::memory_order_acquire);
  return slot.sequence.load(std::memory_order_relaxed) == sequence ? id : PoseId{};
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
  read_sequence_.store(p.sequence, std::memory_order_relaxed);  // push_mm counts the poses never read
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
