// edit_session.h - one edited volume kept in step with what the servo feels: the
// Sculptor (raw volume, GPU brushes, undo), the LiveField (snapshot updated
// brick by brick) and the publication into the servo's TripleBuffer. Used by the scene
// runner (timeline and button edits), `isotouch replay` and `isotouch bench edit`.
//
// Determinism (what record / replay relies on): the same events applied in the same order
// to the same volume give bit-identical snapshots, whether the brushes run on the GPU or on
// the CPU reference (tests/test_brush.cpp: bit for bit). In the headless run, the events
// of tick k are applied AFTER tick k's render, in order, and the new snapshot is published
// before tick k + 1 acquires (so tick k + 1 reads it).
#pragma once
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/session/brush.h"
#include "isotouch/session/live_field.h"
#include "isotouch/servo/triple_buffer.h"

namespace isotouch::session {

/// One edit as the timeline, the button, the API or a recording gives it.
struct EditEvent {
  enum class Kind : std::uint8_t { kBrush, kBeginStroke, kEndStroke, kUndo, kRedo };
  Kind kind = Kind::kBrush;
  long tick = 0;        ///< servo tick after whose render it is applied (headless runs)
  double t_s = 0;       ///< that tick's simulated time [s]
  session::Brush brush;  ///< kBrush only: the brush as applied (centre in grid-world [m])
};
/// "brush", "begin_stroke", "end_stroke", "undo", "redo".
const char* to_string(EditEvent::Kind k);

/// What applying one event did.
struct EditOutcome {
  session::BrushResult brush;                 ///< kBrush: touched / dirty bricks, times
  std::vector<std::uint32_t> restored;       ///< kUndo / kRedo: bricks restored
  session::LiveUpdateStats update;            ///< the snapshot update (zero if nothing changed)
  bool published = false;                    ///< a new snapshot was published
  /// When it was published (right before TripleBuffer::publish), if it was.
  std::chrono::steady_clock::time_point published_at{};
  /// apply() after published_at (publish, the undo step, the log) [ms]; 0 if nothing was published.
  double after_publish_ms = 0;
  /// A brush's undo step could not be recorded (e.g. std::bad_alloc): the edit stands and is
  /// published, the undo / redo history was dropped (undo stops here; a stroke that was open
  /// stays open). Empty: recorded. (The log does not note it: a replay of log() keeps its
  /// history.)
  std::string history_error;
  double wall_ms = 0;                        ///< apply(), everything included [ms]
  std::string error;                         ///< a LiveSession's listener only: apply() threw this (refused)
};

class EditSession {
 public:
  /// @param vol the raw volume (moved in); @param gpu a VulkanContext* (gpu_parts.h), null: CPU brushes and CPU recompute (else GPU
  /// brushes, and the live field's filters on the GPU for large updates: LiveField::create); @param options the
  /// scene's passes, isosurface, background and sample format; @param history_limit_mib undo
  /// memory limit [MiB]. Builds the first snapshot (version 1).
  /// @throws engine::VolumeError / std::invalid_argument as LiveField::create and Sculptor.
  EditSession(engine::Volume vol, GpuParts gpu, const session::LiveFieldOptions& options,
              double history_limit_mib = 256.0);
  ~EditSession();
  EditSession(const EditSession&) = delete;
  EditSession& operator=(const EditSession&) = delete;

  /// Applies `e` and, when samples changed, publishes the new snapshot into `out` (if not
  /// null) as soon as it is built: a brush's undo step is recorded after that (from the live
  /// field's published voxels), outside the edit-to-haptics time. Appends `e` to log().
  /// @throws session::BrushError on an invalid brush.
  /// Strong guarantee: when the new snapshot cannot be built (LiveField::update throws,
  /// e.g. std::bad_alloc), the edit is taken back (a brush's voxels restored on the host and
  /// the device, no undo step recorded; an undo redone; a redo undone), nothing is
  /// published or logged, and the exception goes on: volume and current() still agree.
  EditOutcome apply(const EditEvent& e, servo::TripleBuffer<core::SampleField>* out);
  /// Tests only: `fault` runs just before each snapshot update inside apply(); what it
  /// throws is handled as LiveField::update's own exception. Empty: none.
  void set_update_fault_for_test(std::function<void()> fault);
  /// Tests only: `fault` runs inside apply() right after each brush wrote its voxels (its
  /// undo step is recorded after the snapshot is out); what it throws is handled as a brush that failed part-way (the
  /// brush is taken back, the exception goes on). Empty: none.
  void set_brush_fault_for_test(std::function<void()> fault);
  /// Tests only: `fault` runs inside apply() just before a brush's undo step is recorded
  /// (after its snapshot was published); what it throws is handled as a failed recording.
  void set_history_fault_for_test(std::function<void()> fault);
  /// @throws session::BrushError if the brush's material / empty value cannot be stored in
  /// the snapshot's sample format (fp16: |v| > 65504 or NaN; unorm16: not finite). apply() checks
  /// it before changing anything.
  void check_storable(const session::Brush& b) const;
  /// The newest snapshot (what apply() last published, or the first one).
  std::shared_ptr<const core::SampleField> current() const;
  const engine::Volume& volume() const;
  session::Sculptor& sculptor();
  session::LiveField& live();
  /// The events applied so far, in order: the first log_limit() of them (a recording of a
  /// simulated run is written from it; a live session records as it goes and sets 0).
  const std::vector<EditEvent>& log() const;
  /// At most this many events are kept in log() (default 2^20, about 150 MiB); later ones
  /// are counted in log_dropped() instead, so a long session's memory stays bounded.
  void set_log_limit(std::size_t events);
  std::size_t log_limit() const;
  std::size_t log_dropped() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotouch::session
