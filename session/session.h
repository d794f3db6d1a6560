// session.h - session::Session: one owner for the parts of a live session on a volume (the
// edit session, the triple buffer of its snapshots, the renderer, the live session), built
// in order, torn down in reverse, as a scene object owns its parts. The parts stay usable
// on their own (live_session.h); this is the wiring an embedding program, `isotouch serve`
// and the Python LiveSession would otherwise each write.
#pragma once
#include <exception>
#include <memory>
#include <stdexcept>
#include <string>

#include "isotouch/engine/volume.h"
#include "isotouch/servo/device_io.h"
#include "isotouch/servo/hri.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/session/edit_session.h"
#include "isotouch/session/live_field.h"
#include "isotouch/session/live_session.h"

namespace isotouch::engine {
class VulkanContext;
}

namespace isotouch::session {

/// What Session::open builds.
struct SessionOptions {
  LiveFieldOptions field;                ///< passes, isosurface [value units], background, sample format
  servo::HriParams hri;                  ///< the renderer; its tau and inside must be field.iso's (else open() refuses)
  GpuParts vk = nullptr;                 ///< a VulkanContext* (not owned, outlives the session); null: CPU engine and brushes
  double history_limit_mib = 256.0;      ///< undo memory [MiB]
};

/// A set-up step's outcome: empty `error` = done. `cause` is the exception behind `error`
/// (its type says what failed: engine::VolumeError, io::RecordingError, std::bad_alloc...),
/// for a caller that reports by type.
struct SetupResult {
  std::string error;
  std::exception_ptr cause;
  explicit operator bool() const { return error.empty(); }
  /// For a caller that reports by exception: throws the cause (its type kept), or a
  /// std::runtime_error of `error` where there is none; nothing when it succeeded.
  void throw_if_failed() const;
};

class Session;
/// Session::open's answer: the session, or (session null) why it could not be built.
struct Opened : SetupResult {
  std::unique_ptr<Session> session;
};

class Session {
 public:
  /// Builds the edit session on `volume` (the engine's first snapshot, version 1), publishes
  /// that snapshot into the buffer and builds the HRI renderer. No live session yet (attach()).
  /// Never throws: what fails (a bad option, a volume the engine refuses, memory) is returned.
  static Opened open(engine::Volume volume, const SessionOptions& options);
  /// The same around an edit session already built (a scene's: run::setup_scene).
  static Opened open(std::unique_ptr<EditSession> edits, const servo::HriParams& hri);
  /// Builds the live session on `device` (not owned: it must outlive this Session, or the
  /// next detach()) with `config`, not started (live()->start()). Refused while one is
  /// attached. The returned error names what was refused (the config, a recording that
  /// cannot be created); nothing is built then. `renderer`, when given, is ticked instead of
  /// renderer() (a wrapper of it: a test's stuck renderer); not owned, it must outlive the
  /// live session's servo thread.
  SetupResult attach(servo::HapticDeviceIO& device, LiveSessionConfig config, servo::Renderer* renderer = nullptr);
  /// Stops and frees the live session (as ~LiveSession); the edit session, its snapshots and
  /// the renderer stay, for another attach(). Nothing without one.
  void detach() { live_.reset(); }
  /// Stops and frees the live session first (its servo thread reads the renderer, the
  /// snapshots and the device; an abandoned one ends the process: ~LiveSession), then the rest.
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  EditSession& edits() { return *edits_; }
  servo::TripleBuffer<core::SampleField>& buffer() { return buffer_; }
  servo::HriRenderer& renderer() { return *renderer_; }
  /// Null before attach().
  LiveSession* live() { return live_.get(); }
  const LiveSession* live() const { return live_.get(); }

 private:
  Session() = default;
  // Declared in the order they are built: destroyed in reverse, the live session first.
  std::unique_ptr<EditSession> edits_;
  servo::TripleBuffer<core::SampleField> buffer_;
  std::unique_ptr<servo::HriRenderer> renderer_;
  std::unique_ptr<LiveSession> live_;
};

}  // namespace isotouch::session
