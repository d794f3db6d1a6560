// record.h - recordings of a run: every device input, button and edit with its time, and
// the forces sent (issue 9, item 5). `isotouch run --record FILE` writes one;
// `isotouch replay FILE` plays it back through the same renderer and edit pipeline and
// checks that the forces are reproduced exactly (the simulation is deterministic).
// OWNER: record-replay helper. The lead wrote this contract; the owner may add members but
// keeps these names and meanings.
#pragma once
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "edit_session.h"
#include "vec3.h"

namespace isotouch::app {

/// A bad or unreadable recording. what() names the file, the line (or record) and the
/// field and value at fault.
struct RecordingError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// One servo tick as the device gave it and the servo answered.
struct RecordedTick {
  double t_s = 0;         ///< simulated time of the tick [s]
  core::Vec3 hip_m;       ///< HIP the renderer was given, world [m] (device reading mapped)
  bool button = false;    ///< the device's button
  core::Vec3 force_n;     ///< force sent to the device [N] (checked on replay)
};

struct Recording {
  int format_version = 1;
  std::string scene_path;  ///< the scene file, absolute
  std::string scene_text;  ///< the scene file's bytes at record time (replay refuses a changed file)
  double rate_hz = 0;      ///< servo rate [Hz]
  std::vector<RecordedTick> ticks;  ///< one per tick, tick k at index k
  std::vector<EditEvent> edits;     ///< in the order applied (EditEvent::tick ascending)
};

/// Writes `r` atomically (temp file in the same folder, fsync, rename): a crash leaves the
/// old file or the new one, never half of one. Doubles round-trip exactly.
/// @throws RecordingError naming the file.
void save_recording(const std::string& path, const Recording& r);
/// @throws RecordingError naming the file, the line and the field.
Recording load_recording(const std::string& path);

}  // namespace isotouch::app
