// edit_driver.h - a scene's edits in the live session's simulated mode: the timeline
// submitted at its ticks, the button drill, and every applied edit with its outcome (the
// rows of edits.csv and the edit figures).
#pragma once
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <memory>
#include <string>
#include <vector>

#include "isotouch/session/edit_session.h"
#include "isotouch/session/live_session.h"
#include "isotouch/run/names.h"
#include "isotouch/run/run_metrics.h"
#include "isotouch/io/scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/eval/surface_distance.h"
#include "isotouch/materials/critical_margin.h"

namespace isotouch::run {

/// Voxels inside the scene's isosurface (NaN outside).
long inside_voxels(const engine::Volume& vol, const core::Isosurface& iso);

/// One applied event as edits.csv lists it.
struct EditRow {
  EditEvent event;
  std::string source;     ///< "timeline", "button"
  EditOutcome outcome;
  double removed_mm3 = 0; ///< cumulative removed volume after this event [mm^3]
};

// The scene's edits in a simulated session (LiveSession::run_simulated): the timeline's
// entries are submitted at their tick from the after-tick hook (the API side); the button
// drill at the VHIP is the session's own (servo side). Every applied edit comes back
// through on_applied() with its outcome, for edits.csv and the figures.
class EditDriver {
 public:
  EditDriver(const io::Scene& scene, SceneSetup& setup);

  /// The session's button drill: the scene's brush at the tool, every every_ticks ticks.
  /// Ticks between two applications of a stroke or the button (the scene's every_ticks).
  long every_ticks() const { return scene_.edits.every_ticks; }
  session::ButtonDrill drill() const {
    return {make_brush(at_tool(scene_.edits.brush), targets_, {}, dt_, 0), scene_.edits.every_ticks};
  }

  /// SimulatedRun::after_tick: measures what tick k read, then submits the timeline's
  /// entries due at k (applied before tick k + 1).
  void operator()(session::LiveSession& live, long k, const sim::TraceRow& row);

  /// LiveSessionConfig::on_applied: one row of edits.csv and the figures.
  void on_applied(const EditEvent& applied, const EditOutcome& outcome, session::EditSource source);

  /// A brush applied at the VHIP: with a spherical tool (servo.tool.radius_mm > 0) the VHIP
  /// is the tool's centre and the brush takes the tool's size, reaching one voxel (the
  /// largest spacing: the surface the burr touches lies within one cell of it) past its
  /// surface, so it removes what the burr's surface touches; a point keeps the scene's radius.
  BrushSpec at_tool(const BrushSpec& b) const { return brush_at_tool(scene_, setup_.volume, b); }

  std::vector<char> hip_inside;  ///< per tick: the HIP inside the snapshot that tick read
  /// Contact ticks that read an edited snapshot: the VHIP's true and first-order distance
  /// to the isosurface of that snapshot's volume (dense fp32 CPU chain of the edited voxels).
  struct EditedDistance {
    SurfaceDistance d;
    double first_order_m = 0;
    bool vhip_inside = false;  ///< the VHIP inside that volume's isosurface
  };
  std::map<long, EditedDistance> edited_distance;
  std::vector<EditRow> rows;
  EditFigures figures;
  long inside_before() const { return inside0_; }

 private:
  struct Plan {
    long tick;
    std::size_t entry;
    enum What { kBegin, kApply, kEnd, kUndo, kRedo } what;
  };
  static void submit(session::LiveSession& live, long k, double t, EditEvent::Kind kind, const session::Brush& b);

  /// At tick k (before its edits) the session's volume is the one whose snapshot the tick
  /// read: its dense samples are rebuilt once per snapshot version.
  void measure_edited(long k, const sim::TraceRow& row);

  void note(const std::string& s) { figures.notes.push_back(s); }
  /// Tick k's margin warning: the surface of the brush cutting that tick (add_cutters: its own
  /// centre and radius) against the critical structures' distance; the figures and, on each
  /// entry, a note.
  void watch_margin(long k, const sim::TraceRow& row);
  /// With no timeline brush cutting this tick: the open stroke's brush, else the button drill at the VHIP.
  void add_cutters(const sim::TraceRow& row);
  static bool removes(const session::Brush& b);  ///< a drill or a carve
  /// One line per kind of edit that did nothing (the first time), into figures.notes.
  void said_if_nothing(EditEvent::Kind kind, const session::Brush& b, const EditOutcome& o, double t);

  const Scene& scene_;
  SceneSetup& setup_;
  core::Isosurface iso_;
  session::BrushTargets targets_;
  double dt_, voxel_mm3_;
  long inside0_, inside_now_ = inside0_;
  std::vector<Plan> plan_;
  std::size_t next_ = 0;
  /// The margin warning, one per critical material (setup_.critical's order; else empty).
  std::vector<materials::CriticalMargin> margins_;
  double tool_radius_m_ = 0;  ///< the button drill's radius at the VHIP [m]
  /// A brush that cuts this tick: its surface is what must keep off the critical structures.
  struct Cutter {
    Vec3 centre_m;    ///< grid-world [m]
    double radius_m;  ///< [m]
  };
  std::vector<Cutter> cutters_;          ///< this tick's (add_cutters)
  std::optional<std::size_t> stroke_;    ///< the timeline entry whose stroke is open
  std::shared_ptr<core::SampleField> truth_;
  std::uint64_t truth_version_ = 0;
  bool contact_seen_ = false;
};

/// edits.csv: one row per applied event, centres physical [mm].
std::string edits_csv(const std::vector<EditRow>& rows, const engine::Volume& vol);

}  // namespace isotouch::run
