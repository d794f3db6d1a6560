#include "isotouch/sim/playback_device_io.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace isotouch::sim {

PlaybackDeviceIO::PlaybackDeviceIO(std::vector<PlaybackSample> samples, double period_s, bool loop)
    : samples_(std::move(samples)), T_(period_s), loop_(loop) {
  if (samples_.empty()) throw std::invalid_argument("playback device: no samples");
  if (!(T_ > 0)) throw std::invalid_argument("playback device: period must be > 0 s");
  for (std::size_t i = 1; i < samples_.size(); ++i)
    if (!(samples_[i].t_s > samples_[i - 1].t_s))
      throw std::invalid_argument("playback device: sample " + std::to_string(i) + " time does not increase");
}

Vec3 PlaybackDeviceIO::read_position_m() {
  double t = double(k_++) * T_;
  if (loop_ && duration_s() > 0) t = std::fmod(t, duration_s() + T_);
  if (t < samples_[i_].t_s) i_ = 0;  // looped
  while (i_ + 1 < samples_.size() && samples_[i_ + 1].t_s <= t + 1e-12) ++i_;
  return samples_[i_].position_m;
}

std::vector<TimedPoint> load_timed_points(const std::string& path, const std::string& what, const std::string& expected) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open " + what);
  std::string line;
  std::getline(in, line);  // the header
  std::vector<TimedPoint> out;
  for (int no = 2; std::getline(in, line); ++no) {
    if (line.empty()) continue;
    std::istringstream s(line);
    double v[4];
    for (int i = 0; i < 4; ++i) {
      std::string cell;
      std::getline(s, cell, ',');
      char* end = nullptr;
      v[i] = std::strtod(cell.c_str(), &end);
      if (cell.empty() || *end != '\0' || !std::isfinite(v[i]))
        throw std::runtime_error(path + ":" + std::to_string(no) + ": column " + std::to_string(i + 1) + " ('" + cell +
                                 "') is not a finite number" + (expected.empty() ? "" : " (expected " + expected + ")"));
    }
    if (!out.empty() && !(v[0] > out.back().t_s))
      throw std::runtime_error(path + ":" + std::to_string(no) + ": t_s " + std::to_string(v[0]) + " does not increase");
    out.push_back({v[0], Vec3{v[1], v[2], v[3]}});
  }
  if (out.empty()) throw std::runtime_error(path + ": " + what + " has no rows");
  return out;
}

std::vector<PlaybackSample> load_trace_hips(const std::string& path) {
  {
    std::ifstream in(path);
    std::string header;
    if (in && std::getline(in, header) && header.rfind("t_s,hip_x_m,hip_y_m,hip_z_m", 0) != 0)
      throw std::runtime_error(path + ":1: not a trace.csv (the header must start t_s,hip_x_m,hip_y_m,hip_z_m)");
  }
  std::vector<PlaybackSample> out;
  for (const TimedPoint& r : load_timed_points(path, "the trace")) out.push_back({r.t_s, r.p_m, 0});
  return out;
}

}  // namespace isotouch::sim
