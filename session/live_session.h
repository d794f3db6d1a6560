// live_session.h - a sculpting session in real time: the servo thread, an edit thread and
// a streaming recorder around one EditSession.
//
//   device --read--> ServoThread (SCHED_FIFO) --write--> device
//                      |  TickObserver, inside the tick (no allocation, lock or syscall):
//                      |   - the tick record     -> SpscRing<TickRecord> -> recorder thread
//                      |   - the button drill    -> SpscRing<EditEvent>  -> edit thread
//                      |   - latest VHIP/force   -> seqlock              -> observe()
//   submit() (UI/API) ----------------------------> SpscRing<EditEvent>  -> edit thread
//   edit thread: EditSession::apply (GPU or CPU brushes, live field) -> TripleBuffer::publish
//                -> the servo's next acquire(); each applied edit -> recorder thread
//   recorder thread: every flush interval, the ticks and edits so far as JSON lines
//                (io/record.h, format 3) appended to FILE.part and fdatasync'ed; stop()
//                writes the end record and renames FILE.part to FILE.
//
// Simulated mode (run_simulated(), what `isotouch run` uses): the same session without
// threads, clocked in simulated time on the caller's thread, deterministically: each tick
// runs through sim::run_headless (the one simulated tick loop) with a simulated device;
// after the tick, the frame/API side (SimulatedRun::after_tick) may submit(); then the
// queued edits are applied (API side first, then the button drill), so tick k + 1 reads
// what tick k asked for; the recorder writes a chunk every flush interval of simulated time.
//
// Replay (`isotouch replay FILE`): each tick reads the snapshot version it read live, with
// the dt it measured; edits are applied in the recorded order. A SIGKILLed session leaves
// FILE.part, readable up to its last chunk (load_recording(..., allow_incomplete)).
#pragma once
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <array>
#include <functional>

#include "isotouch/session/edit_session.h"
#include "isotouch/sim/headless.h"
#include "isotouch/io/record.h"
#include "isotouch/servo/renderer.h"
#include "isotouch/servo/servo_thread.h"

namespace isotouch::session {


/// The button drill: while button 0 is down and the probe is in contact (a plane holds the
/// HIP), every `every_ticks` ticks a brush is applied at the VHIP with the force the user
/// applies; a press opens a stroke (one undo step), a release closes it.
struct ButtonDrill {
  Brush brush;          ///< the template: centre and force_n are set per application
  long every_ticks = 1;
};

/// Where an applied edit came from.
enum class EditSource : std::uint8_t {
  kButton,    ///< the button drill at the VHIP (servo side)
  kApi,       ///< submit(): the UI, a scene's timeline, a script
  kEndOfRun,  ///< run_simulated() closing a stroke left open at the end
};

/// Called after each edit the session applies (or refuses, with `error` set), on the edit
/// thread (live) or the caller's thread (simulated). Not real time.
using EditListener = std::function<void(const EditEvent& e, const EditOutcome& outcome, EditSource source)>;

struct LiveSessionConfig {
  servo::ServoThreadConfig servo;  ///< rate, real-time setup, world_T_device (observer: set by the session)
  std::optional<ButtonDrill> drill;
  /// "" = no recording. Else streamed to record_path + ".part" and renamed at stop().
  std::string record_path;
  /// Scene path and text, rate, volume CRC (format set to 3). A rate of 0 is the servo's
  /// (servo.rate_hz); a CRC not set is io::volume_crc32 of the edit session's volume as the
  /// session is built (none without an edit session: then it must be given).
  io::Recording record_header;
  double flush_interval_s = 0.1;   ///< the recorder writes and fdatasyncs a chunk this often
  std::size_t edit_queue = 4096;   ///< requests each edit queue holds
  /// Slots of the servo's version -> first-tick table, from which each publication's
  /// edit-to-haptics latency is taken (a publication still unresolved when this many later
  /// versions have been read loses its latency).
  std::size_t latency_slots = 65536;
  /// Optional: sees every applied edit with its outcome. What it throws is counted
  /// (LiveStats::listener_errors; the edit stands); run_simulated() lets it through.
  EditListener on_applied;
};

/// What run_simulated() clocks: a simulated device pulled by a scripted hand, at the
/// servo rate of the session's config, to the script's end (sim::run_headless).
struct SimulatedRun {
  sim::SimDevice* device = nullptr;          ///< not owned
  const sim::TouchScript* script = nullptr;  ///< not owned
  servo::WorkspaceTransform world_T_device;
  /// Button 0 is down on tick k when k / rate_hz is in some [t0, t1) [s].
  std::vector<std::array<double, 2>> button_down;
  /// After tick k's render and device step, before the edits of tick k are applied: sees
  /// the volume that tick read; may submit() (the timeline) and set row.button.
  sim::TickHook after_tick;
  std::function<void(long, long)> progress;  ///< (ticks done, total) every progress_every ticks
  long progress_every = 250;
};

/// Thrown by LiveSession::stop() when the servo thread was abandoned inside a renderer that
/// did not return (ServoThread::stop): the force is off and the recording was completed (or
/// its error is in what()), but the renderer, its field, the snapshots and the device may
/// still be read by that thread. The caller must not destroy them: it writes what it must
/// and calls end_process_servo_stuck().
class ServoAbandoned : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Ends the process after a ServoAbandoned: prints "PROGRAM: WHAT; ..." on stderr, flushes
/// stdout and stderr, and calls std::_Exit(exit_code::kServoStuck) (no destructors, no atexit
/// handlers: nothing the stuck thread may touch is freed).
[[noreturn]] void end_process_servo_stuck(const std::string& program, const std::string& what) noexcept;

class LiveSession;
/// live.stop(); if it throws ServoAbandoned: on_abandoned(what) (write what must be written:
/// a run folder marked failed; its exceptions are ignored), then
/// end_process_servo_stuck(program, what). Other exceptions from stop() propagate.
void stop_or_end_process(LiveSession& live, const std::string& program,
                         const std::function<void(const std::string& what)>& on_abandoned = {});

/// What a frame loop reads without locks (a consistent copy of one tick).
struct Observed {
  long tick = -1;             ///< -1: no tick yet
  core::Vec3 hip_m, vhip_m, force_n;
  servo::VirtualPlane plane;
  bool contact = false;
  std::uint64_t version = 0;  ///< snapshot version that tick read
  /// The renderer ran this tick (the device's reading was fresh and the session not paused):
  /// vhip_m is a true proxy. False (stale, lost, faulty device, paused): vhip_m and force_n
  /// are zeros, no place, and hip_m the device's last reading (before any: its default).
  bool rendered = false;
};

/// Counters of a running or stopped session.
/// Bin width of LiveStats::period_error_p99_us's histogram [us].
inline constexpr double kPeriodBinUs = 2.0;
/// Bins of that histogram; the last one starts at kPeriodRangeUs [us].
inline constexpr std::size_t kPeriodBins = 4096;
inline constexpr double kPeriodRangeUs = double(kPeriodBins - 1) * kPeriodBinUs;

struct LiveStats {
  long ticks = 0, missed_deadlines = 0, faults = 0;
  /// Each counted once its listener (LiveSessionConfig::on_applied) has returned: a caller
  /// that sees an edit counted sees what the listener did with it (serve's mirror, a save).
  long edits_requested = 0, edits_applied = 0, edits_refused = 0;
  long edits_dropped = 0;     ///< the edit queue was full (servo side or submit())
  /// A stroke's begin or end with nothing to apply: a begin inside an open stroke (it joins
  /// it), an end inside an outer stroke or with none open (its begin was dropped, or an undo
  /// ended it).
  long edits_merged = 0;
  /// Every edit requested so far has been applied, refused, dropped or merged.
  bool settled() const { return edits_applied + edits_refused + edits_dropped + edits_merged >= edits_requested; }
  long ticks_not_recorded = 0;  ///< the recorder's ring was full (recording incomplete)
  long publications = 0;
  /// Per published edit: from the start of the tick that asked for it (servo side) or the
  /// submit() call (API) to the start of the first tick that read its snapshot [ms].
  std::vector<double> edit_to_haptics_ms;
  /// Latencies taken so far; edit_to_haptics_ms holds the newest of them (all, unless
  /// stats() was asked for fewer).
  std::size_t edit_to_haptics_taken = 0;
  /// p99 (nearest rank) of |measured period - nominal period| over the ticks so far [us],
  /// from a histogram of kPeriodBins bins of kPeriodBinUs (a bin's upper edge); -1 before
  /// the second tick. Available while the servo runs. Past the histogram's range (the last
  /// bin collects every error from kPeriodRangeUs on) it is kPeriodRangeUs and
  /// period_error_p99_beyond is set: the p99 is at least that, its value unknown.
  double period_error_p99_us = -1;
  bool period_error_p99_beyond = false;
  std::string setup_note;     ///< what the system refused at start (SCHED_FIFO, pinning, locking)
  std::string record_error;   ///< "" or why the recording failed
  long listener_errors = 0;   ///< calls of LiveSessionConfig::on_applied that threw (the edit stands)
  /// The servo's live passivity stage (servo/live_passivity.h); empty without a servo thread
  /// (a simulated session): nothing was observed, which zeros would not say.
  std::optional<servo::PassivityStats> passivity;
  std::string listener_error; ///< what the first of them said
};

class LiveSession final {
 public:
  /// `edits` holds the volume and publishes into `buffer` (its first snapshot already
  /// published); `renderer` and `device` are used by the servo thread only. None owned.
  /// @throws std::invalid_argument on a bad config (rate, flush interval), io::RecordingError
  ///         if the recording cannot be created (names the file).
  LiveSession(EditSession& edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
              servo::HapticDeviceIO& device, LiveSessionConfig config);
  /// A session for run_simulated() only (start() refuses: there is no device). `edits` may be
  /// null: a session that only feels its published snapshot (submit() then refuses).
  LiveSession(EditSession* edits, servo::TripleBuffer<core::SampleField>& buffer, servo::Renderer& renderer,
              LiveSessionConfig config);
  /// stop()s if running; a servo thread abandoned there ends the process
  /// (end_process_servo_stuck): the caller would free what that thread reads next.
  ~LiveSession();
  LiveSession(const LiveSession&) = delete;
  LiveSession& operator=(const LiveSession&) = delete;

  /// Starts the recorder, the edit thread, then the servo thread. Returns what the system
  /// refused of the real-time setup ("" if nothing), as ServoThread::start.
  /// @throws std::logic_error if nothing was ever published into the buffer (the servo
  ///         would feel nothing: zero force every tick); names the missing publish().
  std::string start();
  /// Paused: zero force every tick (the servo keeps running, edits still apply).
  void pause(bool paused);
  /// Stops the servo (its last force an exact zero), then the edit thread (requests still
  /// queued are dropped and counted), then the recorder (end record, fsync, rename).
  /// Idempotent. @throws io::RecordingError if the recording could not be completed;
  ///         ServoAbandoned (after the rest has stopped and the recording was completed,
  ///         within about 1 s) if the renderer did not return: the force is off and the
  ///         servo thread abandoned (ServoThread::stop); the renderer and device must
  ///         outlive any return of it (end_process_servo_stuck()).
  void stop();

  /// Simulated mode: runs every tick of `run` on this thread (see the file comment), closes a
  /// stroke left open, and returns the trace (one row per tick). Once per session, instead
  /// of start(); stop() afterwards completes the recording. Edits that throw propagate.
  /// @throws std::logic_error if the session was started or already ran; std::invalid_argument
  ///         without a device or script; what an edit or the recorder throws.
  std::vector<sim::TraceRow> run_simulated(const SimulatedRun& run);
  /// Simulated mode a piece at a time, for a caller that owns the clock (a window's frame
  /// loop on a simulated clock): runs the session's next `ticks` ticks exactly as
  /// run_simulated() runs its ticks (tick k at k / rate_hz, its hand target from run.script
  /// at that time: the script's clock is the session's; after_tick; then the queued edits),
  /// and returns their rows. Any number of calls (with any device and script: the caller
  /// keeps the device from one call to the next) instead of start() or run_simulated();
  /// edits submitted between calls are applied after the next tick. Run in pieces of any
  /// size, the ticks, edits and recording are those of one run_simulated(). An edit that
  /// throws is refused as in a live session (counted; on_applied sees its error).
  /// @throws std::logic_error after start(), run_simulated() or finish_simulated();
  ///         std::invalid_argument without a device or script or with ticks < 0; what the recorder throws.
  std::vector<sim::TraceRow> step_simulated(const SimulatedRun& run, long ticks);
  /// Ends simulated mode: applies the edits submitted since the last tick (after it) and
  /// closes a stroke left open (EditSource::kEndOfRun); no more ticks. run_simulated() ends
  /// with it; a stepped session calls it before stop() (stop() alone drops what is queued).
  /// Idempotent; nothing outside simulated mode. Edits that throw propagate (after
  /// run_simulated()) or are refused (stepped), as in the ticks before.
  void finish_simulated();

  /// An edit from the UI or the API (one producer thread). Its tick and t_s are set when it
  /// is applied. False if the queue is full.
  bool submit(const EditEvent& e);
  /// The latest tick, consistent, without locks. Any thread.
  Observed observe() const;
  /// Time since start() on the servo's clock [s].
  double elapsed_s() const;
  /// After stop(): complete; while running: the counters only. `latency_tail` limits
  /// edit_to_haptics_ms to the newest that many latencies (a frame loop's panel reads the
  /// recent ones in O(tail), not the whole session's list).
  LiveStats stats(std::size_t latency_tail = SIZE_MAX) const;
  /// The servo thread (its real-time set-up, period errors after stop()); null in a
  /// session for run_simulated() only.
  const servo::ServoThread* servo_thread() const;

 private:
  // Everything the servo, edit and recorder threads share (rings, seqlock, threads, the
  // recording's file): defined in live_session.cpp, so this header (and isotouch.h) does
  // not include them. The servo thread's observer is the Impl itself: each tick calls its
  // on_tick() directly, through no forwarding of this class.
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotouch::session
