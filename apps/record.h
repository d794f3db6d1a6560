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

/// THE FILE (format_version 1): JSON lines (nlohmann-json), one record per line, in order:
///   {"format":"isotouch-recording","format_version":1,"scene_path":S,"scene_text":S,"rate_hz":D}
///   {"k":0,"t":D,"hip":[D,D,D],"button":B,"force":[D,D,D]}          one per tick, k = 0, 1, ...
///   {"edit":"brush","tick":K,"t":D,"brush":{...}}   after tick K's line (K ascending): the
///        edits applied after tick K's render; "brush" holds every engine::Brush field
///        (kind, centre_m [m, grid-world], radius_m, strength, falloff, targets {material,
///        empty, density_scale}, force_n, force_threshold_n, rate, dt_s); kinds "brush",
///        "begin_stroke", "end_stroke", "undo", "redo" (brush optional for the last four)
///   {"end":true,"ticks":N,"edits":M}                 last line: a file without it is truncated
/// Doubles are written shortest-round-trip (nlohmann's dtoa) and read back bit for bit
/// (subnormals and -0.0 included); the brush's float targets are checked to be floats.
/// Every number must be finite (times, HIP, forces, brush fields); t strictly ascending.
inline constexpr const char* kRecordingFormat = "isotouch-recording";

/// The file's text for `r` (what save_recording writes). @throws RecordingError naming
/// `name`, the tick or edit and the field when `r` cannot be written faithfully (a
/// non-finite number, edits not ascending or outside the ticks).
std::string recording_text(const Recording& r, const std::string& name);
/// Parses a recording's text; `name` is used in messages. Never crashes on garbage: every
/// problem is a RecordingError naming `name`, the line, the record and the field and value.
Recording parse_recording(const std::string& text, const std::string& name);

/// Writes `r` atomically (temp file in the same folder, fsync, rename): a crash leaves the
/// old file or the new one, never half of one. Doubles round-trip exactly.
/// @throws RecordingError naming the file.
void save_recording(const std::string& path, const Recording& r);
/// @throws RecordingError naming the file, the line and the field.
Recording load_recording(const std::string& path);

}  // namespace isotouch::app
