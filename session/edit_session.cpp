// edit_session.cpp - EditSession: Sculptor + LiveField + publication (session/edit_session.h).
#include "isotouch/session/edit_session.h"

#include <chrono>
#include <cmath>
#include <exception>
#include <functional>
#include <string>

namespace isotouch::session {

const char* to_string(EditEvent::Kind k) {
  switch (k) {
    case EditEvent::Kind::kBrush: return "brush";
    case EditEvent::Kind::kBeginStroke: return "begin_stroke";
    case EditEvent::Kind::kEndStroke: return "end_stroke";
    case EditEvent::Kind::kUndo: return "undo";
    case EditEvent::Kind::kRedo: return "redo";
  }
  return "?";
}

namespace {
/// A brush only moves voxels toward its material / empty values (or averages them), so a
/// snapshot format that holds the volume holds the result if it holds both targets. Checked
/// BEFORE the volume changes: LiveField::update would refuse the edited volume after the
/// edit, leaving the volume edited and the snapshot not.
void check_storable_targets(const session::Brush& b, core::SampleFormat f) {
  if (f == core::SampleFormat::kFp32) return;  // fp32 stores what the volume holds
  for (const auto& [name, v] : {std::pair<const char*, float>{"material", b.targets.material},
                                std::pair<const char*, float>{"empty", b.targets.empty}}) {
    const bool bad = f == core::SampleFormat::kFp16 ? !(std::abs(v) <= 65504.f) : !std::isfinite(v);
    if (bad)
      throw session::BrushError(std::string("brush: targets.") + name + " = " + std::to_string(v) +
                               " cannot be stored in the " + core::to_string(f) + " snapshot");
  }
}
/// The message of the exception in flight (in a catch block); never throws.
void note_exception(std::string& to) noexcept {
  try {
    try {
      throw;
    } catch (const std::exception& x) {
      to = x.what();
    } catch (...) {
      to = "unknown exception";
    }
  } catch (...) {  // (no memory for the message)
  }
}
}  // namespace

struct EditSession::Impl {
  std::unique_ptr<session::LiveField> live;
  std::unique_ptr<session::Sculptor> sculptor;
  std::vector<EditEvent> log;
  std::size_t log_limit = std::size_t(1) << 20;
  std::size_t log_dropped = 0;
  std::function<void()> update_fault;
  std::function<void()> brush_fault;
  std::function<void()> history_fault;
};

EditSession::EditSession(engine::Volume vol, GpuParts gpu, const session::LiveFieldOptions& options,
                         double history_limit_mib)
    : impl_(std::make_unique<Impl>()) {
  impl_->live = session::LiveField::create(vol, options, gpu);
  impl_->sculptor = std::make_unique<session::Sculptor>(std::move(vol), gpu, history_limit_mib);
}
EditSession::~EditSession() = default;

void EditSession::check_storable(const session::Brush& b) const {
  check_storable_targets(b, impl_->live->options().format);
}

EditOutcome EditSession::apply(const EditEvent& e, servo::TripleBuffer<core::SampleField>* out) {
  const auto t0 = std::chrono::steady_clock::now();
  EditOutcome o;
  if (e.kind == EditEvent::Kind::kBrush) check_storable(e.brush);
  session::Sculptor& sc = *impl_->sculptor;
  // What a brush may change: if its snapshot cannot be built, these bricks go back to the
  // live field's published voxels (the volume as of its current snapshot, which a failed
  // update leaves alone), so that volume and snapshot never disagree. Its undo step is
  // recorded from there too, once the snapshot is out (off the edit-to-haptics path).
  std::vector<std::uint32_t> touched;
  std::vector<std::uint32_t> changed;
  switch (e.kind) {
    case EditEvent::Kind::kBrush:
      touched = session::touched_bricks(sc.volume().grid, e.brush);
      try {
        o.brush = sc.apply_unrecorded(e.brush);
        if (impl_->brush_fault) impl_->brush_fault();
      } catch (...) {
        // A brush that failed part-way (an allocation after it wrote a brick) is taken back
        // the same way: the volume stays the published one.
        try {
          sc.roll_back_apply(touched, impl_->live->published_voxels().data());
        } catch (...) {
        }
        throw;
      }
      changed = o.brush.dirty;
      break;
    case EditEvent::Kind::kBeginStroke: sc.begin_stroke(); break;
    case EditEvent::Kind::kEndStroke: sc.end_stroke(); break;
    case EditEvent::Kind::kUndo: o.restored = sc.undo(); changed = o.restored; break;
    case EditEvent::Kind::kRedo: o.restored = sc.redo(); changed = o.restored; break;
  }
  // The brush's undo step, from the volume as of the snapshot before it (a brush that changed
  // nothing records none: outside a stroke it only drops the redo branch, as a stroke of its
  // own that changed nothing). An edit that stands without its step would make undoing older
  // strokes give a state that never existed: then the history goes, and the outcome says why.
  const std::vector<std::uint32_t> none;
  auto record_undo = [&](const std::vector<std::uint32_t>& ids) noexcept {
    if (e.kind != EditEvent::Kind::kBrush) return;
    try {
      if (impl_->history_fault && !ids.empty()) impl_->history_fault();
      sc.record_applied(ids, impl_->live->published_voxels().data());
    } catch (...) {
      sc.drop_history();
      note_exception(o.history_error);
    }
  };
  if (changed.empty()) record_undo(none);
  if (!changed.empty()) {
    try {
      if (impl_->update_fault) impl_->update_fault();
      const session::LiveField::OnCommit on_commit = [&](const std::shared_ptr<const core::SampleField>& snap) {
        o.published_at = std::chrono::steady_clock::now();
        if (out) out->publish(snap);
        record_undo(touched);
      };
      (void)impl_->live->update(sc.volume(), changed, &o.update, on_commit);
    } catch (...) {
      // LiveField::update publishes nothing when it throws: take the edit back. The
      // update's exception is the one that goes on.
      try {
        if (e.kind == EditEvent::Kind::kBrush) sc.roll_back_apply(touched, impl_->live->published_voxels().data());
        else if (e.kind == EditEvent::Kind::kUndo) (void)sc.redo();
        else (void)sc.undo();
      } catch (...) {
      }
      throw;
    }
    o.published = true;
  }
  if (impl_->log.size() < impl_->log_limit) impl_->log.push_back(e);
  else ++impl_->log_dropped;
  const auto t_end = std::chrono::steady_clock::now();
  o.wall_ms = std::chrono::duration<double, std::milli>(t_end - t0).count();
  if (o.published) o.after_publish_ms = std::chrono::duration<double, std::milli>(t_end - o.published_at).count();
  return o;
}

void EditSession::set_update_fault_for_test(std::function<void()> fault) { impl_->update_fault = std::move(fault); }
void EditSession::set_brush_fault_for_test(std::function<void()> fault) { impl_->brush_fault = std::move(fault); }
void EditSession::set_history_fault_for_test(std::function<void()> fault) { impl_->history_fault = std::move(fault); }

std::shared_ptr<const core::SampleField> EditSession::current() const { return impl_->live->current(); }
const engine::Volume& EditSession::volume() const { return impl_->sculptor->volume(); }
session::Sculptor& EditSession::sculptor() { return *impl_->sculptor; }
session::LiveField& EditSession::live() { return *impl_->live; }
const std::vector<EditEvent>& EditSession::log() const { return impl_->log; }
void EditSession::set_log_limit(std::size_t events) {
  impl_->log_limit = events;
  if (impl_->log.size() > events) {
    impl_->log_dropped += impl_->log.size() - events;
    impl_->log.resize(events);
    impl_->log.shrink_to_fit();
  }
}
std::size_t EditSession::log_limit() const { return impl_->log_limit; }
std::size_t EditSession::log_dropped() const { return impl_->log_dropped; }

}  // namespace isotouch::session
