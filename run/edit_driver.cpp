#include "isotouch/run/edit_driver.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "isotouch/core/field_view.h"
#include "isotouch/engine/pass_desc.h"
#include "isotouch/materials/critical_distance.h"
#include "isotouch/run/text.h"

namespace isotouch::run {

long inside_voxels(const engine::Volume& vol, const core::Isosurface& iso) {
  long n = 0;
  for (float v : vol.voxels) n += iso.contains(double(v)) ? 1 : 0;
  return n;
}

EditDriver::EditDriver(const Scene& scene, SceneSetup& setup)
    : scene_(scene), setup_(setup), iso_(setup.live.iso),
      targets_(session::default_targets(setup.volume, iso_)),
      dt_(scene.edits.every_ticks / scene.hri.rate_hz),
      voxel_mm3_(setup.volume.grid.spacing_m.x * setup.volume.grid.spacing_m.y * setup.volume.grid.spacing_m.z * 1e9),
      inside0_(inside_voxels(setup.volume, iso_)) {
  const EditsSpec& e = scene.edits;
  {
    const session::Brush b = make_brush(e.brush, targets_, {}, dt_, 0);
    const double range = std::abs(double(b.targets.material) - double(b.targets.empty));
    figures.drill_rate_value_per_n_s = b.rate;
    figures.drill_removal_per_n_s = range > 0 ? b.rate / range : 0.0;
  }
  for (std::size_t i = 0; i < e.timeline.size(); ++i) {
    const TimedEdit& t = e.timeline[i];
    const long k0 = edit_tick(t.t_s, scene.hri.rate_hz);
    if (t.kind == "undo" || t.kind == "redo") {
      plan_.push_back({k0, i, t.kind == "undo" ? Plan::kUndo : Plan::kRedo});
    } else if (t.duration_s <= 0) {
      plan_.push_back({k0, i, Plan::kApply});
    } else {
      const long k1 = std::max(k0 + 1, edit_tick(t.t_s + t.duration_s, scene.hri.rate_hz));
      plan_.push_back({k0, i, Plan::kBegin});
      long last = k0;
      for (long k = k0; k < k1; k += e.every_ticks) {
        plan_.push_back({k, i, Plan::kApply});
        last = k;
      }
      plan_.push_back({last, i, Plan::kEnd});
    }
  }
  tool_radius_m_ = at_tool(e.brush).radius_mm * 1e-3;
  for (const SceneSetup::CriticalStructure& c : setup.critical) {
    margins_.emplace_back(c.margin_m);
    figures.critical.push_back({c.name, c.margin_m});
  }
  std::stable_sort(plan_.begin(), plan_.end(), [](const Plan& a, const Plan& b) { return a.tick < b.tick; });
  const double end_s = setup.script.duration_s;
  for (std::size_t i = 0; i < e.timeline.size(); ++i)
    if (e.timeline[i].t_s > end_s) {
      ++figures.timeline_after_end;
      note("edits.timeline[" + std::to_string(i) + "] (" + e.timeline[i].kind + " at t = " + fmt(e.timeline[i].t_s, 4) +
           " s) is after the script's end (" + fmt(end_s, 4) + " s): never applied");
    }
}

void EditDriver::operator()(session::LiveSession& live, long k, const sim::TraceRow& row) {
  const double t = double(k) / scene_.hri.rate_hz;
  contact_seen_ = contact_seen_ || row.contact;
  cutters_.clear();
  if (row.contact && row.version > 1) measure_edited(k, row);
  // What tick k read (before this tick's edits): the release check's inside test.
  hip_inside.push_back(iso_.contains(core::FieldView(*setup_.session->current()).value(row.hip_m)) ? 1 : 0);
  for (; next_ < plan_.size() && plan_[next_].tick <= k; ++next_) {
    const Plan& p = plan_[next_];
    const TimedEdit& te = scene_.edits.timeline[p.entry];
    switch (p.what) {
      case Plan::kUndo: submit(live, k, t, EditEvent::Kind::kUndo, {}); break;
      case Plan::kRedo: submit(live, k, t, EditEvent::Kind::kRedo, {}); break;
      case Plan::kBegin:
        submit(live, k, t, EditEvent::Kind::kBeginStroke, {});
        stroke_ = p.entry;
        break;
      case Plan::kEnd:
        submit(live, k, t, EditEvent::Kind::kEndStroke, {});
        stroke_.reset();
        break;
      case Plan::kApply: {
        if (te.at_vhip && !contact_seen_ && !row.contact) {
          if (figures.vhip_before_contact++ == 0)
            note("t = " + fmt(t, 4) + " s: edits.timeline[" + std::to_string(p.entry) + "] (" + te.kind +
                 " at \"vhip\") came before any contact: applied at the HIP in free space");
        }
        const Vec3 c = te.at_vhip ? row.vhip_m : setup_.volume.to_grid(te.at_m);
        const double f = te.brush.force_n >= 0 ? te.brush.force_n : core::norm(row.force_n);
        const session::Brush b = make_brush(te.at_vhip ? at_tool(te.brush) : te.brush, targets_, c, dt_, f);
        submit(live, k, t, EditEvent::Kind::kBrush, b);
        if (removes(b)) cutters_.push_back({b.centre_m, b.radius_m});
        ++figures.timeline_brushes;
        break;
      }
    }
  }
  if (!margins_.empty()) watch_margin(k, row);
}

bool EditDriver::removes(const session::Brush& b) {
  return b.kind == session::BrushKind::kDrill || b.kind == session::BrushKind::kCarve;
}

// The brushes that cut at tick k: the timeline's drill and carve applications of this tick;
// between the applications of an open timeline stroke, its brush where the next one goes;
// else the button drill's burr at the VHIP.
void EditDriver::add_cutters(const sim::TraceRow& row) {
  if (!cutters_.empty()) return;
  if (stroke_) {
    const TimedEdit& te = scene_.edits.timeline[*stroke_];
    const session::Brush b = make_brush(te.at_vhip ? at_tool(te.brush) : te.brush, targets_,
                                        te.at_vhip ? row.vhip_m : setup_.volume.to_grid(te.at_m), dt_, 0);
    if (removes(b)) {
      cutters_.push_back({b.centre_m, b.radius_m});
      return;
    }
  }
  cutters_.push_back({row.vhip_m, tool_radius_m_});
}

void EditDriver::on_applied(const EditEvent& applied, const EditOutcome& outcome, session::EditSource source) {
  if (!outcome.error.empty()) return;  // simulated: the session rethrows; the run fails
  EditEvent e = applied;
  e.tick = std::max(0L, applied.tick - 1);  // edits.csv: the tick after which it was applied
  const EditEvent::Kind kind = e.kind;
  const char* src = source == session::EditSource::kButton ? "button"
                    : source == session::EditSource::kApi  ? "timeline"
                                                            : "end of run";
  EditRow r{e, src, outcome, 0};
  if (kind == EditEvent::Kind::kBrush) {
    ++figures.brushes;
    if (source == session::EditSource::kButton) ++figures.button_brushes;
    if (figures.first_edit_t_s < 0) figures.first_edit_t_s = e.t_s;
  }
  if (kind == EditEvent::Kind::kUndo) ++figures.undos;
  if (kind == EditEvent::Kind::kRedo) ++figures.redos;
  said_if_nothing(kind, e.brush, r.outcome, e.t_s);
  if (!outcome.history_error.empty())
    note("t = " + fmt(e.t_s, 4) + " s: the brush's undo step could not be recorded (" + outcome.history_error +
         "): the undo history was dropped, the edit stands");
  if (r.outcome.published) inside_now_ = inside_voxels(setup_.session->volume(), iso_);
  r.removed_mm3 = double(inside0_ - inside_now_) * voxel_mm3_;
  rows.push_back(std::move(r));
}

void EditDriver::submit(session::LiveSession& live, long k, double t, EditEvent::Kind kind, const session::Brush& b) {
  EditEvent e;
  e.kind = kind;
  e.tick = k;
  e.t_s = t;
  if (kind == EditEvent::Kind::kBrush) e.brush = b;
  if (!live.submit(e)) throw std::runtime_error("edits: the session's edit queue is full at t = " + fmt(t, 4) + " s");
}

void EditDriver::watch_margin(long k, const sim::TraceRow& row) {
  const double t = double(k) / scene_.hri.rate_hz;
  add_cutters(row);
  for (std::size_t m = 0; m < margins_.size(); ++m) {
    const SceneSetup::CriticalStructure& cs = setup_.critical[m];
    materials::CriticalMargin& margin = margins_[m];
    double surface = std::numeric_limits<double>::infinity();
    for (const Cutter& c : cutters_) surface = std::min(surface, cs.distance->lower_bound(c.centre_m) - c.radius_m);
    const long before = margin.entries();
    margin.update(t, 1.0 / scene_.hri.rate_hz, surface);
    if (margin.entries() > before && margin.entries() <= 3)
      note("t = " + fmt(t, 4) + " s: WARNING the burr's surface entered the " + fmt(margin.margin_m() * 1e3, 4) +
           " mm margin of the critical " + cs.name + " (" + fmt(surface * 1e3, 4) + " mm away)" +
           (margin.entries() == 3 ? "; later entries are counted in summary.json edits.critical_margin" : ""));
    EditFigures::CriticalFigures& f = figures.critical[m];
    f.entries = margin.entries();
    f.time_inside_s = margin.time_inside_s();
    f.closest_approach_m = margin.closest_m();
    f.first_entry_t_s = margin.first_entry_t_s();
  }
}

void EditDriver::measure_edited(long k, const sim::TraceRow& row) {
  if (!truth_ || truth_version_ != row.version) {
    truth_ = std::make_shared<core::SampleField>(
        std::move(*engine::run_chain_cpu(setup_.session->volume(), scene_passes(scene_)).samples));
    truth_->background = setup_.truth->background;
    truth_version_ = row.version;
  }
  edited_distance[k] = {distance_to_isosurface(*truth_, scene_.hri.tau, row.vhip_m),
                        first_order_distance(*truth_, scene_.hri.tau, row.vhip_m),
                        iso_.contains(core::FieldView(*truth_).value(row.vhip_m))};
}

void EditDriver::said_if_nothing(EditEvent::Kind kind, const session::Brush& b, const EditOutcome& o, double t) {
  const bool undo = kind == EditEvent::Kind::kUndo, redo = kind == EditEvent::Kind::kRedo;
  if ((undo || redo) && o.restored.empty()) {
    long& n = undo ? figures.undo_nothing : figures.redo_nothing;
    if (n++ == 0) note("t = " + fmt(t, 4) + " s: " + (undo ? "undo with nothing to undo" : "redo with nothing to redo"));
  }
  if (kind != EditEvent::Kind::kBrush || !o.brush.dirty.empty()) return;
  ++figures.brushes_changing_nothing;
  const auto& g = setup_.volume.grid;
  const Vec3 lo = g.to_world(Vec3{-0.5, -0.5, -0.5}),
             hi = g.to_world(Vec3{g.dims[0] - 0.5, g.dims[1] - 0.5, g.dims[2] - 0.5});
  const Vec3& c = b.centre_m;
  const double r = b.radius_m;
  const bool outside = c.x + r < lo.x || c.y + r < lo.y || c.z + r < lo.z || c.x - r > hi.x || c.y - r > hi.y || c.z - r > hi.z;
  if (outside && figures.brushes_outside++ == 0)
    note("t = " + fmt(t, 4) + " s: a " + session::to_string(b.kind) + " brush entirely outside the volume changed nothing");
  else if (!outside && figures.brushes_changing_nothing - figures.brushes_outside == 1)
    note("t = " + fmt(t, 4) + " s: a " + session::to_string(b.kind) + " brush changed no voxel (" +
         (b.kind == session::BrushKind::kDrill && !(b.force_n > b.force_threshold_n)
              ? "the force, " + fmt(b.force_n, 3) + " N, was not above the drill's threshold of " + fmt(b.force_threshold_n, 3) + " N"
              : std::string("nothing to remove or add there")) +
         "); " + "later ones are counted in summary.json edits.did_nothing");
}

// edits.csv: one row per applied event, centres physical [mm].
std::string edits_csv(const std::vector<EditRow>& rows, const engine::Volume& vol) {
  std::ostringstream s;
  s << "t_s,tick,event,source,centre_x_mm,centre_y_mm,centre_z_mm,radius_mm,force_n,dirty_bricks,"
       "recomputed_bricks,published,version,apply_ms,removed_mm3\n"
    << std::setprecision(9);
  for (const EditRow& r : rows) {
    const bool brush = r.event.kind == EditEvent::Kind::kBrush;
    const Vec3 c = brush ? vol.to_physical(r.event.brush.centre_m) * 1e3 : Vec3{};
    s << r.event.t_s << ',' << r.event.tick << ',' << (brush ? session::to_string(r.event.brush.kind) : to_string(r.event.kind))
      << ',' << r.source << ',' << c.x << ',' << c.y << ',' << c.z << ',' << (brush ? r.event.brush.radius_m * 1e3 : 0.0)
      << ',' << (brush ? r.event.brush.force_n : 0.0) << ','
      << (brush ? r.outcome.brush.dirty.size() : r.outcome.restored.size()) << ',' << r.outcome.update.recomputed << ','
      << int(r.outcome.published) << ',' << r.outcome.update.version << ',' << r.outcome.wall_ms << ',' << r.removed_mm3
      << '\n';
  }
  return s.str();
}

}  // namespace isotouch::run
