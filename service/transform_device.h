// transform_device.h - a tracked tool's TRANSFORM stream as a haptic device, and the force
// the servo renders for it, for `isotouch serve`. Part of isotouch::igtl_device.
//
// Frames: the stream's translation is in mm in the tracker's RAS (Slicer's and PLUS's
// frame); the registration (registration.h: p_image = R p + t, identity unless set) takes it
// into the image's RAS, and `offset_mm` (RAS) is added to that (the workspace transform that
// maps a tracker's workspace into the volume); the result is the point in the volume's
// physical frame, converted here to the grid frame [m] the servo works in (engine/volume.h),
// so the servo's world_T_device is the identity. The force goes the other way: grid axes ->
// LPS -> RAS [N] (image), and to_tracker_n() -> the tracker's RAS (R^T f) for the stream's
// client.
#pragma once
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>

#include "isotouch/service/device_echo.h"
#include "isotouch/service/registration.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/latest_value.h"
#include "isotouch/servo/stall_rule.h"

namespace isotouch::service {

class TransformDevice final : public servo::HapticDeviceIO {
 public:
  /// The volume whose physical frame the stream's points are in. Only while no servo runs.
  void set_frame(const engine::Volume& v, const core::Vec3& offset_mm);
  /// A TRANSFORM's translation [mm, tracker RAS] arrived now (network thread); `stamp`: its
  /// header's raw time stamp, echoed in the force that answers it. The registration in force
  /// now maps it into the image.
  void push_mm(const double t_mm[3], std::uint64_t stamp = 0);
  /// The tracker's registration to the image, for the poses pushed from now on and the forces
  /// sent back (to_tracker_n). Any thread, any time.
  void set_registration(const Registration& r);
  Registration registration() const { return reg_cell_.load(); }
  /// An image-RAS vector (a force [N]) in the tracker's RAS: R^T f. Any thread, lock-free.
  core::Vec3 to_tracker_n(const core::Vec3& f_ras) const { return reg_cell_.load().to_tracker(f_ras); }
  /// The newest pose: its sequence number (0: none yet), when it arrived [ns, steady], its stamp.
  struct PoseId {
    std::uint64_t sequence = 0;
    std::int64_t received_ns = 0;
    std::uint64_t stamp = 0;
  };
  PoseId newest_pose() const;
  /// The pose numbered `sequence` if it is among the last kRecent pushed (its sequence 0
  /// otherwise): the reply thread answers a pose the servo answered after a newer one came.
  /// Lock-free, any thread.
  static constexpr std::size_t kRecent = 16;
  PoseId recent_pose(std::uint64_t sequence) const;
  /// When the servo last wrote a force [ns, steady] (0: never).
  std::int64_t force_written_ns() const { return echo_.written_ns(); }
  /// Messages pushed so far.
  long pushed() const { return pushed_.load(); }
  /// Poses the servo never read: a newer one had arrived before its tick (or during a swap);
  /// counted when the newer one is pushed (the sum of overtaken_gaps()).
  long overtaken() const;
  /// Those poses by how soon the next came after them: < 0.1, 0.1-0.3, 0.3-0.7, 0.7-1.3 and
  /// over 1.3 ms (a burst from the sender, or a tick the servo did not make in between).
  static constexpr int kGapBins = 5;
  std::array<long, kGapBins> overtaken_gaps() const;

  // Servo thread: no allocation, lock or syscall (the clock is the vDSO's).
  core::Vec3 read_position_m() override { return read().position_m; }
  servo::DeviceReading read() override;
  void write_force_n(const core::Vec3& f) override {
    echo_.store(f);
    rule_.write(f, last_.sequence, now_ns());  // stamped: the stall is timed from the write
  }
  /// The servo's stall time (ServoThread: 2.5 periods): the reply thread sends a zero within
  /// it + its poll of a stall, and the servo ramps in after (the stall rule, stall_rule.h).
  const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) override {
    return rule_.enable(on, stall_s, 0.05, now_ns());
  }
  /// The stream client's device's peak force [N] (the scene's device.link_max_force_n; the
  /// client drives it, isotouch cannot ask it). Only while no servo runs.
  void set_max_force_n(double f_n) { max_force_n_ = f_n; }
  /// That peak as the device's force limit: the servo's gate clamps to min(scene, it) and
  /// limits the force's rate to it over 2 ms (servo/force_gate.h).
  servo::DeviceCaps caps() const override {
    servo::DeviceCaps c;
    c.name = "serve's TRANSFORM stream";
    c.max_force_n = max_force_n_;
    return c;
  }
  /// When the stream's next pose is due: the servo ticks just after it (input_phase.h).
  servo::InputPhase input_phase() const override { return arrivals_.phase(); }
  /// Reply thread only: before its first look_force(), then once a poll (clock read first).
  void restart_force(std::int64_t t_ns) { rule_.restart(t_ns); }
  servo::StallLook look_force(std::int64_t t_ns) { return rule_.look(t_ns); }
  /// Times the reply thread took the force off because the servo stopped writing.
  std::uint64_t stalls() const { return rule_.stalls(); }

  /// The servo's force and the volume's frame, for the TRANSFORMs sent out (device_echo.h).
  const RasEcho& echo() const { return echo_; }
  core::Vec3 force_ras_n(double stall_s) const { return echo_.force_ras_n(stall_s); }
  core::Vec3 grid_to_ras_mm(const core::Vec3& g) const { return echo_.grid_to_ras_mm(g); }

  static std::int64_t now_ns() { return RasEcho::now_ns(); }

 private:
  struct Pose {
    double mm[3] = {0, 0, 0};
    std::int64_t received_ns = 0;  // 0: nothing yet
    std::uint64_t sequence = 0;
    std::uint64_t stamp = 0;
  };
  servo::LatestValue<Pose> pose_;
  Pose last_;  // servo thread
  std::mutex push_mu_;
  servo::ArrivalClock arrivals_;  // under push_mu_
  Registration reg_;                          // push_mu_: the one push_mm applies
  servo::LatestValue<Registration> reg_cell_;  // written under push_mu_: the one forces go back through
  std::atomic<long> pushed_{0};
  std::atomic<std::uint64_t> read_sequence_{0};  // the last pose the servo read (servo thread)
  std::array<std::atomic<long>, kGapBins> overtaken_gaps_{};  // under push_mu_
  // The last kRecent poses' ids by sequence % kRecent, each slot a sequence lock (its
  // sequence 0 while written); written under push_mu_.
  struct RecentSlot {
    std::atomic<std::uint64_t> sequence{0};
    std::atomic<std::int64_t> received_ns{0};
    std::atomic<std::uint64_t> stamp{0};
  };
  std::array<RecentSlot, kRecent> recent_;
  RasEcho echo_;
  servo::StallRule rule_;
  core::Vec3 offset_mm_;
  double max_force_n_ = 3.3;
};

}  // namespace isotouch::service
