// critical_margin.h - the margin warning around the critical structures: counts the times the
// burr's surface enters the margin, the time it spends inside and its closest approach.
#pragma once
#include <limits>

namespace isotouch::materials {

/// Fed once per servo tick with the burr's surface distance to the nearest critical voxel
/// (CriticalDistance::lower_bound of the burr's centre minus the burr's radius) [m].
class CriticalMargin {
 public:
  /// @param margin_m the warning distance [m] (the critical materials' largest margin_mm).
  explicit CriticalMargin(double margin_m) : margin_m_(margin_m) {}

  /// Tick at time t_s [s] lasting dt_s [s], the burr's surface `surface_m` [m] from the
  /// structure (negative: it overlaps it). @return true while inside the margin.
  bool update(double t_s, double dt_s, double surface_m) {
    closest_m_ = surface_m < closest_m_ ? surface_m : closest_m_;
    const bool in = surface_m < margin_m_;
    if (in && !inside_) {
      ++entries_;
      if (first_entry_t_s_ < 0) first_entry_t_s_ = t_s;
    }
    if (in) time_inside_s_ += dt_s;
    inside_ = in;
    return in;
  }

  double margin_m() const { return margin_m_; }
  long entries() const { return entries_; }                 ///< outside -> inside transitions
  double time_inside_s() const { return time_inside_s_; }   ///< [s]
  double closest_m() const { return closest_m_; }           ///< smallest surface distance seen [m] (+inf: none)
  double first_entry_t_s() const { return first_entry_t_s_; }  ///< [s], -1: never entered
  bool inside() const { return inside_; }

 private:
  double margin_m_;
  long entries_ = 0;
  double time_inside_s_ = 0;
  double closest_m_ = std::numeric_limits<double>::infinity();
  double first_entry_t_s_ = -1;
  bool inside_ = false;
};

}  // namespace isotouch::materials
