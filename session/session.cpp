#include "isotouch/session/session.h"

#include <string>

#include <utility>

namespace isotouch::session {
namespace {

SetupResult failed(const char* step) {
  SetupResult r;
  r.cause = std::current_exception();
  try {
    std::rethrow_exception(r.cause);
  } catch (const std::exception& e) {
    r.error = std::string(step) + ": " + e.what();
  } catch (...) {
    r.error = std::string(step) + ": an exception that is not a std::exception";
  }
  return r;
}

}  // namespace

void SetupResult::throw_if_failed() const {
  if (error.empty()) return;
  if (cause) std::rethrow_exception(cause);
  throw std::runtime_error(error);
}

Opened Session::open(engine::Volume volume, const SessionOptions& options) {
  const core::Isosurface& iso = options.field.iso;
  if (options.hri.tau != iso.tau || options.hri.inside != iso.inside) {
    Opened o;  // the felt surface would not be the one whose bricks are active
    o.error = "session: the renderer's isosurface (hri.tau " + std::to_string(options.hri.tau) +
              ") is not the field's (field.iso.tau " + std::to_string(iso.tau) + "), or their inside sides differ";
    return o;
  }
  std::unique_ptr<EditSession> edits;
  try {
    edits = std::make_unique<EditSession>(std::move(volume), options.vk, options.field, options.history_limit_mib);
  } catch (...) {
    Opened o;
    static_cast<SetupResult&>(o) = failed("session: building the edit session");
    return o;
  }
  return open(std::move(edits), options.hri);
}

Opened Session::open(std::unique_ptr<EditSession> edits, const servo::HriParams& hri) {
  Opened o;
  if (!edits) {
    o.error = "session: no edit session was given";
    return o;
  }
  try {
    std::unique_ptr<Session> s(new Session());
    s->edits_ = std::move(edits);
    s->buffer_.publish(s->edits_->current());
    s->renderer_ = std::make_unique<servo::HriRenderer>(hri);
    o.session = std::move(s);
  } catch (...) {
    static_cast<SetupResult&>(o) = failed("session: building the renderer");
  }
  return o;
}

SetupResult Session::attach(servo::HapticDeviceIO& device, LiveSessionConfig config, servo::Renderer* renderer) {
  if (live_) return {"session: attach() while a live session is attached (detach() it first)", {}};
  try {
    servo::Renderer& ticked = renderer ? *renderer : static_cast<servo::Renderer&>(*renderer_);
    live_ = std::make_unique<LiveSession>(*edits_, buffer_, ticked, device, std::move(config));
  } catch (...) {
    return failed("session: building the live session");
  }
  return {};
}

Session::~Session() = default;

}  // namespace isotouch::session
