// app.cpp - isotouch-sculpt: run_sculpt, the session's steps in order (the Sculpt class:
// sculpt_app.h; its methods by idea in app_*.cpp), and the helpers several of those files use.
#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

std::string fixed(double v, int p) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(p) << v;
  return s.str();
}

/// The stats panel's volume line: dims, spacing, orientation.
std::string volume_line(const engine::Volume& v) {
  const auto& d = v.grid.dims;
  const Vec3& s = v.grid.spacing_m;
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]) + ", " + fixed(s.x * 1e3, 2) +
         " x " + fixed(s.y * 1e3, 2) + " x " + fixed(s.z * 1e3, 2) + " mm, " + v.orientation();
}

Sculpt::~Sculpt() {
#if ISOTOUCH_WITH_IMGUI
  g_panels = nullptr;
#endif
  if (g_input == &input) g_input = nullptr;
}

}  // namespace isotouch::sculpt::detail

namespace isotouch::sculpt {

using detail::Sculpt;

int run_sculpt(const Options& o, std::ostream& log, std::optional<Options>* reopen) {
  Sculpt s(o, log, reopen);
  if (!s.load_input() || !s.place_probe()) return 1;
  s.open_journal();
  if (!s.open_window()) return 1;
  s.open_panels();
  if (!s.open_edits() || !s.restore_journal()) return 1;
  const session::LiveSessionConfig cfg = s.session_config();
  if (!s.open_device() || !s.start_session(cfg)) return 1;
  s.init_tools();
  s.frame_loop();
  return s.finish();
}

}  // namespace isotouch::sculpt
