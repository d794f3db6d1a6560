// stuck_renderer.h - a test seam for isotouch.LiveSession: a renderer that stops returning
// at a given servo tick, so that a Python test can drive LiveSession.stop() through
// session::ServoAbandoned (the force turned off, the session never freed).
#pragma once

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>

#include "isotouch/servo/renderer.h"

namespace isotouch::python {

/// The environment variable that turns the seam on: a servo tick number >= 1.
inline constexpr const char* kStuckAtTickEnv = "ISOTOUCH_PY_TEST_STUCK_AT_TICK";

/// Ticks `inner` until tick `stuck_at`, which never returns (it sleeps until the process
/// ends). It must outlive the servo thread: the Live that owns it is then leaked (DeleteLive).
class StuckRenderer final : public servo::Renderer {
 public:
  StuckRenderer(servo::Renderer& inner, long stuck_at) : inner_(inner), stuck_at_(stuck_at) {}
  /// Freed while the servo thread is inside tick(): the use after free the binding must never
  /// allow (DeleteLive leaks an abandoned session), made a loud, certain abort here.
  ~StuckRenderer() override {
    if (inside_.load()) {
      std::fprintf(stderr, "isotouch test seam: the stuck renderer was freed under its servo thread\n");
      std::abort();
    }
  }
  const char* name() const override { return "stuck (test seam)"; }
  void reset() override { inner_.reset(); }
  servo::HriTick tick(const core::FieldView& field, const core::Vec3& hip_world_m, double dt_s) override {
    if (++ticks_ == stuck_at_) {
      inside_.store(true);
      for (;;) std::this_thread::sleep_for(std::chrono::milliseconds(10));  // touches nothing
    }
    return inner_.tick(field, hip_world_m, dt_s);
  }

 private:
  servo::Renderer& inner_;
  long stuck_at_;
  long ticks_ = 0;
  std::atomic<bool> inside_{false};
};

/// The seam's tick from the environment: 0 when the variable is not set; a value that is not
/// a whole number >= 1 is refused naming the variable and the value (std::invalid_argument).
inline long stuck_at_tick_from_env() {
  const char* v = std::getenv(kStuckAtTickEnv);
  if (!v || !*v) return 0;
  char* end = nullptr;
  errno = 0;
  const long n = std::strtol(v, &end, 10);
  if (errno != 0 || *end != '\0' || n < 1)
    throw std::invalid_argument(std::string(kStuckAtTickEnv) + "='" + v + "': must be a servo tick number >= 1");
  return n;
}

}  // namespace isotouch::python
