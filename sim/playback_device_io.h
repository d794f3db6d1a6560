// playback_device_io.h - a device that replays recorded HIP positions at their recorded
// times (a trace.csv of `isotouch run`, or a recording), so recorded motions drive
// regression tests and live sessions.
#pragma once
#include "isotouch/sim/servo_names.h"
#include <cstdint>
#include <string>
#include <vector>

#include "isotouch/servo/device_io.h"
#include "isotouch/core/vec3.h"

namespace isotouch::sim {

/// One recorded position.
struct PlaybackSample {
  double t_s = 0;            ///< recorded time [s], increasing
  Vec3 position_m;           ///< HIP, device frame [m]
  std::uint32_t buttons = 0;
};

/// Synchronous device: tick k (the k-th read since construction) reads the last sample whose
/// time is <= k * period (the first sample before it). Forces written are kept (last_force_n)
/// and otherwise discarded. After the last sample it holds the last position (loop = false)
/// or starts over.
class PlaybackDeviceIO final : public servo::HapticDeviceIO {
 public:
  /// @throws std::invalid_argument without samples, with a period <= 0 or times not increasing.
  PlaybackDeviceIO(std::vector<PlaybackSample> samples, double period_s, bool loop = false);
  Vec3 read_position_m() override;
  std::uint32_t buttons() override { return samples_[i_].buttons; }
  void write_force_n(const Vec3& f) override { last_ = f; }
  const Vec3& last_force_n() const { return last_; }
  double duration_s() const { return samples_.back().t_s; }
  long ticks_read() const { return k_; }

 private:
  std::vector<PlaybackSample> samples_;
  double T_;
  bool loop_;
  long k_ = 0;
  std::size_t i_ = 0;
  Vec3 last_;
};

/// One row of a CSV whose first four columns are a time [s] and a position x, y, z [m].
struct TimedPoint {
  double t_s;
  Vec3 p_m;
};

/// Reads the first four columns of every row after the header of `path` (`what` names the
/// file's kind in errors: "the trace", "the hand path"): finite numbers, times strictly
/// increasing; later columns are ignored.
/// @throws std::runtime_error naming the file, line, column and value (`expected` is appended
/// to a bad number's message), or a file without rows.
std::vector<TimedPoint> load_timed_points(const std::string& path, const std::string& what,
                                          const std::string& expected = "");

/// Reads the HIP columns of a trace.csv (`t_s,hip_x_m,hip_y_m,hip_z_m,...`, as written by
/// `isotouch run`): positions in the frame the file uses (the caller maps them).
/// @throws std::runtime_error naming the file, line and column.
std::vector<PlaybackSample> load_trace_hips(const std::string& path);

}  // namespace isotouch::sim
