// record.h - recordings of a run: every device input, button and edit with its time, and
// the forces sent. `isotouch run --record FILE` writes one;
// `isotouch replay FILE` plays it back through the same renderer and edit pipeline and
// checks that the forces, VHIPs and snapshot versions are reproduced exactly (the simulation
// is deterministic).
#pragma once
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "isotouch/session/edit_session.h"
#include "isotouch/core/isosurface.h"
#include "isotouch/core/vec3.h"

namespace isotouch::io {

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
  core::Vec3 force_n;     ///< the renderer's force [N] (before a live session's ramp-in and clamp; 0 on a held tick; checked on replay)
  /// Format 2: the VHIP after the tick, world [m], and the SampleField::version of the
  /// snapshot the tick read (both checked on replay; version 0 = not recorded, format 1).
  core::Vec3 vhip_m;
  std::uint64_t version = 0;
  /// Format 2: the tick was a fault (non-finite or implausible HIP, or a non-finite force:
  /// zero force sent); written only when true, checked on replay.
  bool fault = false;
  /// Format 3 (a live session): the measured period the renderer was given [s]; 0 on the
  /// first tick (the renderer then takes the nominal one).
  double dt_s = 0;
  /// Format 3: the renderer was not ticked (paused, device not ok, a live session's last
  /// tick: the stop's zero): zero force, no VHIP (0, 0, 0). A replay skips it. Written if true.
  bool held = false;
  /// Format 3: the renderer was reset before this tick (the first good tick after held
  /// ones that ended its contact state); its dt is then 0. Written only when true.
  bool reset = false;
  /// Format 3 (a live servo's passivity stage, servo/live_passivity.h): the clock its
  /// observer stepped on [s] (the device's own where it has one) and the force actually
  /// sent [N], device axes: the observer's inputs beside the HIP. Absent on a tick the stage
  /// did not step (held, ramp start) and in files written before; not checked on replay
  /// (the replay checks the renderer, before the stage).
  std::optional<double> passivity_clock_s;
  core::Vec3 sent_n;
};

/// The edit session a recording's edits were applied through, where it is not the scene's
/// "edits" section (the sculpting app's brushes): replay builds the same one.
struct RecordedEditSession {
  bool gpu_brushes = false;         ///< brushes on the GPU (else the CPU reference)
  double history_limit_mib = 256;   ///< the undo memory limit [MiB], > 0
  /// The servo's edit ease period (HriParams::edit_period_s) [s] the session ran with; 0: not
  /// recorded (replay then takes the scene's). An edit session the scene does not describe
  /// sets its own period, and the forces depend on it.
  double edit_period_s = 0;
};

struct Recording {
  /// 3: a session::LiveSession's (`isotouch run --record`, simulated time, and `run --live
  /// --record`), streamed while it runs: ticks carry their measured dt (0: the nominal
  /// period), and edits the servo tick count when they were applied. 2 (a simulated run's,
  /// written whole at the end by earlier versions) and 1 (no VHIP, version or volume
  /// checksum) are still read.
  int format_version = 2;
  /// False: the file has no end record (a live session killed before it stopped); every
  /// whole line before the cut was read. Only format 3 files may be incomplete.
  bool complete = true;
  std::string scene_path;  ///< the scene file, absolute
  std::string scene_text;  ///< the scene file's bytes at record time: what replay runs (the file may change or move)
  double rate_hz = 0;      ///< servo rate [Hz]
  /// Format 2: volume_crc32() of the volume the run loaded (replay refuses another volume).
  std::optional<std::uint32_t> volume_crc32;
  /// Format 3: the edit session of the sculpting app (absent: the scene's "edits" section).
  std::optional<RecordedEditSession> edit_session;
  /// Format 3, an edit journal of `isotouch serve` (io/journal.h): the isovalue its session
  /// ran at when a client's `isovalue V` rebuilt it (absent: the volume's own). The edits
  /// replay on the volume of volume_crc32 at any isovalue (a brush carries its targets);
  /// a restore builds the session at this one.
  std::optional<core::Isosurface> isovalue;
  /// Format 3, an edit journal: after how many of `edits` the undo history started afresh
  /// (each `isovalue V` rebuilt the session on its edited volume): ascending, each at most
  /// the number of edits. A restore drops the history there, so an undo after it undoes
  /// what it undid in the session (nothing before the rebuild).
  std::vector<std::size_t> history_restarts;
  std::vector<RecordedTick> ticks;  ///< one per tick, tick k at index k
  std::vector<session::EditEvent> edits;     ///< in the order applied (session::EditEvent::tick ascending)
};

/// THE FILE (format_version 2): JSON lines (nlohmann-json), one record per line, in order:
///   {"format":"isotouch-recording","format_version":2,"scene_path":S,"scene_text":S,"rate_hz":D,
///    "volume_crc32":U}
///   {"k":0,"t":D,"hip":[D,D,D],"button":B,"force":[D,D,D],"vhip":[D,D,D],"version":U}
///                                                    one per tick, k = 0, 1, ...; a fault
///                                                    tick also has "fault":true
///   (format 3 may add "edit_session":{"gpu_brushes":B,"history_limit_mib":D} to the
///    header: the edit session the edits went through, where the scene has no "edits";
///    and, in an edit journal, "isovalue":{"tau":D,"inside":"above"|"below"} and
///    "history_restarts":[N,...]: Recording::isovalue, Recording::history_restarts)
///   (format_version 1, still read: no volume_crc32, no vhip, no version)
///   {"edit":"brush","tick":K,"t":D,"brush":{...}}   after tick K's line (K ascending): the
///        edits applied after tick K's render; "brush" holds every session::Brush field
///        (kind, centre_m [m, grid-world], radius_m, strength, falloff, targets {material,
///        empty, density_scale}, force_n, force_threshold_n, rate, dt_s); kinds "brush",
///        "begin_stroke", "end_stroke", "undo", "redo" (brush optional for the last four)
///   {"end":true,"ticks":N,"edits":M}                 last line: a file without it is truncated
/// format_version 3 (live sessions) differs in these places: each tick line also has
/// "dt":D (the measured period given to the renderer [s], 0 on the first tick), "held":true
/// on a tick where the renderer was not ticked (paused, device not ok) and "reset":true on
/// one before which it was reset (each written only when true), "pt":D and "sent":[D,D,D]
/// (the passivity stage's clock [s] and the force sent [N], both or neither), and an edit
/// line's "tick" is the number of servo ticks that had run when the edit was applied (edits
/// in the order applied, ticks ascending; the line may come later than that tick's line:
/// the streams of ticks and edits are written in chunks). A format 3 file without its end
/// record is read with complete = false when the caller allows it (load_recording's
/// allow_incomplete): what was written before a crash or SIGKILL stays usable.
/// Doubles are written shortest-round-trip (nlohmann's dtoa) and read back bit for bit
/// (subnormals and -0.0 included); the brush's float targets are checked to be floats.
/// Every number must be finite (times, HIP, forces, brush fields); t strictly ascending.
inline constexpr const char* kRecordingFormat = "isotouch-recording";

/// The scene file a recording names: scene_path, a relative one against `recording_dir`
/// (committed recordings name their scene relative to themselves). Replay parses the
/// recorded scene_text as if it were there, so a relative volume path resolves against the
/// folder the scene was in when recorded, wherever the scene file is now.
std::string recorded_scene_path(const Recording& r, const std::string& recording_dir);

/// CRC-32 (zlib) of a volume's dims, spacing, origin, direction and voxel bytes: what replay
/// checks the volume by.
std::uint32_t volume_crc32(const engine::Volume& volume);

/// The file's text for `r` (what save_recording writes). @throws RecordingError naming
/// `name`, the tick or edit and the field when `r` cannot be written faithfully (a
/// non-finite number, edits not ascending or outside the ticks).
std::string recording_text(const Recording& r, const std::string& name);
/// Parses a recording's text; `name` is used in messages. Never crashes on garbage: every
/// problem is a RecordingError naming `name`, the line, the record and the field and value.
/// allow_incomplete: a format 3 file without its end record (a partial last line dropped)
/// is returned with complete = false instead of refused.
Recording parse_recording(const std::string& text, const std::string& name, bool allow_incomplete = false);

/// The lines recording_text() is made of, for a recorder that streams a format 3 file:
/// each ends with '\n'. @throws RecordingError naming `name` and the field (non-finite numbers).
std::string recording_header_line(const Recording& r, const std::string& name);
std::string recording_tick_line(long k, const RecordedTick& t, int format_version, const std::string& name);
std::string recording_edit_line(const session::EditEvent& e, const std::string& name);
std::string recording_end_line(std::size_t ticks, std::size_t edits);

/// Writes `r` atomically (temp file in the same folder, fsync, rename): a crash leaves the
/// old file or the new one, never half of one. Doubles round-trip exactly.
/// @throws RecordingError naming the file.
void save_recording(const std::string& path, const Recording& r);
/// @throws RecordingError naming the file, the line and the field.
Recording load_recording(const std::string& path, bool allow_incomplete = false);

}  // namespace isotouch::io
