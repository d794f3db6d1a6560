// app_input.cpp - isotouch-sculpt's input: the script (and the built-in --bench script), GLFW's
// callbacks, the keys, the camera and the hand (sculpt_app.h).

#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

namespace {

/// Waits (at most 2 s) until the window's framebuffer has a size it was asked for in screen
/// units, so that a scripted resize takes effect on the same frame every run: the server's
/// size first, then its event, which updates the window's framebuffer_size().
void wait_for_size(Window& window, int w, int h) {
  const auto t0 = Clock::now();
  for (;;) {
    int ww = 0, wh = 0;
    glfwGetWindowSize(window.handle(), &ww, &wh);
    if ((ww == w && wh == h) || ms_since(t0) > 2000) break;
    glfwWaitEventsTimeout(0.01);
  }
  glfwPollEvents();  // the size event the server sent before its answer
}

}  // namespace

Input* g_input = nullptr;  // GLFW callbacks (one window)

// The Dear ImGui panels' share of GLFW's events (no-ops in a build without them): ImGui
// sees every event, and a press or wheel over a panel is not the sculpt's.
#if ISOTOUCH_WITH_IMGUI
Overlay* g_panels = nullptr;
bool panels_want_mouse() { return g_panels && g_panels->wants_mouse(); }
bool panels_want_keyboard() { return g_panels && g_panels->wants_keyboard(); }
void panels_button(GLFWwindow* w, int b, int action, int mods) {
  if (g_panels) g_panels->mouse_button(w, b, action, mods);
}
void panels_scroll(GLFWwindow* w, double dx, double dy) {
  if (g_panels) g_panels->scroll(w, dx, dy);
}
void panels_key(GLFWwindow* w, int key, int scancode, int action, int mods) {
  if (g_panels) g_panels->key(w, key, scancode, action, mods);
}
void on_char(GLFWwindow* w, unsigned int c) {
  if (g_panels) g_panels->character(w, c);
}
void panels_cursor() {
  if (g_panels) g_panels->cursor_moved();
}
#else
bool panels_want_mouse() { return false; }
bool panels_want_keyboard() { return false; }
void panels_button(GLFWwindow*, int, int, int) {}
void panels_scroll(GLFWwindow*, double, double) {}
void panels_key(GLFWwindow*, int, int, int, int) {}
void on_char(GLFWwindow*, unsigned int) {}
void panels_cursor() {}
#endif

void on_cursor(GLFWwindow* w, double x, double y) {
  const double s = Window::of(w).pixels_per_unit();  // the cached sizes: no X round trip per motion event
  g_input->px = x * s;
  g_input->py = y * s;
  g_input->cursor_seen = true;
  panels_cursor();
}
void on_button(GLFWwindow* w, int b, int action, int mods) {
  panels_button(w, b, action, mods);
  if (action == GLFW_PRESS && panels_want_mouse()) return;  // a click on a panel
  const int i = b == GLFW_MOUSE_BUTTON_LEFT ? 0 : b == GLFW_MOUSE_BUTTON_RIGHT ? 1 : b == GLFW_MOUSE_BUTTON_MIDDLE ? 2 : -1;
  if (i >= 0) g_input->down[i] = action == GLFW_PRESS;
}
void on_scroll(GLFWwindow* w, double dx, double dy) {
  panels_scroll(w, dx, dy);
  if (!panels_want_mouse()) g_input->scroll += dy;
}
void on_drop(GLFWwindow*, int n, const char** paths) {
  for (int i = 0; i < n; ++i) g_input->drops.emplace_back(paths[i]);
}
void on_key(GLFWwindow* w, int key, int scancode, int action, int mods) {
  panels_key(w, key, scancode, action, mods);
  if (panels_want_keyboard()) return;  // typing into a panel's field
  if (action == GLFW_PRESS || action == GLFW_REPEAT)
    g_input->keys.push_back({key, (mods & GLFW_MOD_CONTROL) != 0, (mods & GLFW_MOD_SHIFT) != 0});
}

/// --bench: the probe onto the surface at the centre, then rounds of a 30-frame carve stroke
/// moving right, undo, and 36 frames of camera moves (orbit, zoom, orbit back, zoom back),
/// each drawn whole, the camera back where the round began. The rounds start at event
/// kBenchRoundStart and repeat until the servo has ticked --bench-ticks times (Sculpt::run_script).
constexpr std::size_t kBenchRoundStart = 5;
std::string bench_script_text() {
  std::ostringstream t;
  t << R"({"events": [{"orbit": [20, 0]}, {"cursor": [0.5, 0.45]}, {"tool": "carve", "radius_mm": 8, "strength": 0.5},
    {"wait": "contact", "timeout_s": 30}, {"after_frames": 5, "scroll": 2},
    {"cursor": [0.5, 0.45]}, {"wait": "contact", "timeout_s": 30}, {"press": "left"})";
  for (int i = 0; i < 30; ++i) t << R"(, {"cursor": [)" << 0.5 + 0.004 * i << ", 0.45]}";
  t << R"(, {"release": "left"}, {"wait": "edits", "timeout_s": 30}, {"key": "z", "mods": ["ctrl"]},
    {"wait": "edits", "timeout_s": 30})";
  // Then the camera moves every frame: frames drawn whole.
  for (int i = 0; i < 12; ++i) t << R"(, {"orbit": [3, 1]})";
  for (int i = 0; i < 6; ++i) t << R"(, {"zoom": 1.05})";
  for (int i = 0; i < 12; ++i) t << R"(, {"orbit": [-3, -1]})";
  for (int i = 0; i < 6; ++i) t << R"(, {"zoom": )" << 1.0 / 1.05 << "}";
  t << R"(, {"after_frames": 10, "quit": true}]})";
  return t.str();
}

// --- the script, the input, the camera and the hand (the frame loop's) ------------------------

double Sculpt::script_now_s() const {
  return o.sim_clock ? session->elapsed_s() : std::chrono::duration<double>(Clock::now() - t_wall0).count();
}

/// The script's events due this frame (a wait holds it). True when the script quits.
bool Sculpt::run_script(const std::array<int, 2>& fb, std::vector<std::string>& shots) {
  bool quit = false;
  while (next_event < script.size()) {
    const InputEvent& ev = script[next_event];
    if (wait_frames > 0) break;
    if (ev.kind == InputEvent::Kind::kWait && script_waits(ev)) break;
    if (ev.kind == InputEvent::Kind::kQuit && another_bench_round()) continue;
    apply_event(ev, fb, shots, quit);
    ++next_event;
    if (next_event < script.size()) wait_frames = script[next_event].after_frames;
    if (iso_ctl.committed) break;  // the rest of the script runs in the restarted session
  }
  return quit;
}

/// The built-in bench's quit: true (the script goes back to the rounds' start) while the
/// servo has ticked fewer than --bench-ticks times, so that its misses while sculpting are
/// counted over at least that many ticks.
bool Sculpt::another_bench_round() {
  if (!bench_rounds) return false;
  ++bench_rounds_run;
  if (session->stats().ticks >= o.bench_ticks) return false;
  next_event = kBenchRoundStart;
  wait_frames = script[next_event].after_frames;
  return true;
}

/// A wait event: true while it holds the script (not met, not timed out).
bool Sculpt::script_waits(const InputEvent& ev) {
  if (!waiting) {
    waiting = true;
    wait_since = script_now_s();
    shown_at_wait = latency_ms.size();
  }
  bool met;
  if (ev.text == "contact") {
    met = session->observe().contact;
  } else if (ev.text == "change") {
    met = latency_ms.size() > shown_at_wait;  // a brush that changed voxels, drawn
  } else {
    std::lock_guard<std::mutex> lock(feed.mu);
    met = feed.events_done >= events_submitted && feed.pending.empty() && brushes_measured >= feed.brushes_done;
  }
  if (!met && script_now_s() - wait_since < ev.timeout_s) return true;
  if (!met) log << "script   event " << next_event << ": wait for " << ev.text << " timed out after " << ev.timeout_s << " s\n";
  waiting = false;
  return false;
}

/// One script event: the input it stands for, or what it asks of the camera, tool or window.
void Sculpt::apply_event(const InputEvent& ev, const std::array<int, 2>& fb, std::vector<std::string>& shots, bool& quit) {
  using EK = InputEvent::Kind;
  switch (ev.kind) {
    case EK::kCursor:
      input.px = ev.xy[0] * (fb[0] - 1);
      input.py = ev.xy[1] * (fb[1] - 1);
      input.cursor_seen = true;
      break;
    case EK::kPress: input.down[ev.button] = true; break;
    case EK::kRelease: input.down[ev.button] = false; break;
    case EK::kScroll:
      if (ev.ctrl) camera.zoom_by(std::pow(1.1, ev.xy[0]));
      else input.scroll += ev.xy[0];
      break;
    case EK::kKey: input.keys.push_back({ev.key, ev.ctrl, ev.shift}); break;
    case EK::kTool:
      tool.kind = *tool_from_name(ev.text);
      if (ev.radius_mm > 0) tool.radius_m = ev.radius_mm * 1e-3;
      if (ev.strength >= 0) tool.strength = ev.strength;
      break;
    case EK::kOrbit: camera.orbit(ev.xy[0], ev.xy[1]); break;
    case EK::kZoom: camera.zoom_by(ev.xy[0]); break;
    case EK::kScreenshot: shots.push_back((shot_dir / ev.text).string()); break;
    case EK::kResize:
      glfwSetWindowSize(window->handle(), int(ev.xy[0]), int(ev.xy[1]));
      if (o.sim_clock) wait_for_size(*window, int(ev.xy[0]), int(ev.xy[1]));  // the same frame every run
      break;
    case EK::kQuit: quit = true; break;
    case EK::kDrop: input.drops.push_back(ev.text); break;
    case EK::kIso:
      iso_ctl.value = ev.xy[0];
      iso_ctl.committed = true;
      iso_ctl.how = "hand (the script's iso)";
      break;
    case EK::kPreset:
      if (const auto v = preset_value(iso_ctl, ev.text)) {
        iso_ctl.value = *v;
        iso_ctl.committed = true;
        iso_ctl.how = "the preset " + ev.text;
      } else {
        status = "no preset \"" + ev.text + "\" for this volume";
        log << "sculpt   " << status << "\n";
      }
      break;
    case EK::kWait: break;
  }
}

/// Keys (before a restart: an undo in the same frame goes into the volume it carries), the
/// isovalue, dropped files, camera drags and the wheel. True when this session ends.
bool Sculpt::take_input(const std::array<int, 2>& fb) {
  for (const Input::Key& k : input.keys) handle_key(k);
  input.keys.clear();
  if (iso_ctl.committed && restart_at(iso_ctl.value)) {
    restarting = true;
    return true;
  }
  for (const std::string& path : input.drops) drop_queue.push_back(path);
  input.drops.clear();
  if (poll_load()) return true;
  steer_camera(fb);
  return false;
}

void Sculpt::handle_key(const Input::Key& k) {
  using K = session::EditEvent::Kind;
  session::EditEvent e;
  switch (k.key) {
    case GLFW_KEY_1: tool.kind = session::BrushKind::kAdd; break;
    case GLFW_KEY_2: tool.kind = session::BrushKind::kCarve; break;
    case GLFW_KEY_3: tool.kind = session::BrushKind::kSmooth; break;
    case GLFW_KEY_4: tool.kind = session::BrushKind::kDrill; break;
    case GLFW_KEY_LEFT_BRACKET: step_radius(tool, false); break;
    case GLFW_KEY_RIGHT_BRACKET: step_radius(tool, true); break;
    case GLFW_KEY_MINUS: step_strength(tool, false); break;
    case GLFW_KEY_EQUAL: step_strength(tool, true); break;
    case GLFW_KEY_H: overlay = !overlay; break;
    case GLFW_KEY_LEFT: camera.orbit(-5, 0); break;
    case GLFW_KEY_RIGHT: camera.orbit(5, 0); break;
    case GLFW_KEY_UP: camera.orbit(0, 5); break;
    case GLFW_KEY_DOWN: camera.orbit(0, -5); break;
    case GLFW_KEY_PAGE_UP: camera.zoom_by(1.2); break;
    case GLFW_KEY_PAGE_DOWN: camera.zoom_by(1 / 1.2); break;
    case GLFW_KEY_R: camera.cam = run::default_camera(vol); say_camera(); break;
    case GLFW_KEY_COMMA: roll(-1); break;
    case GLFW_KEY_PERIOD: roll(1); break;
    case GLFW_KEY_ESCAPE:
    case GLFW_KEY_Q: glfwSetWindowShouldClose(window->handle(), GLFW_TRUE); break;
    case GLFW_KEY_S:
      if (k.ctrl) save(save_path);
      break;
    case GLFW_KEY_E:
      if (k.ctrl) export_mesh(export_path);
      break;
    case GLFW_KEY_C:  // clip: cut away the half toward the eye, through the camera's target
      if (style.clip) style.clip.reset();
      else style.clip = engine::ClipPlane{camera.cam.target_m ? *camera.cam.target_m : vol.grid.centre_m(), -view.forward};
      break;
    case GLFW_KEY_Z:
    case GLFW_KEY_Y:
      if (!k.ctrl || stroke.open()) break;  // not in the middle of a stroke
      e.kind = (k.key == GLFW_KEY_Y || k.shift) ? K::kRedo : K::kUndo;
      if (session->submit(e)) ++events_submitted;
      break;
    default: break;
  }
}

/// Right drag orbits, middle drag pans, the wheel pushes the hand deeper (Ctrl: zooms).
void Sculpt::steer_camera(const std::array<int, 2>& fb) {
  const bool ctrl = !o.sim_clock && (glfwGetKey(window->handle(), GLFW_KEY_LEFT_CONTROL) == GLFW_PRESS ||
                                     glfwGetKey(window->handle(), GLFW_KEY_RIGHT_CONTROL) == GLFW_PRESS);
  const double dx = input.px - input.last_px, dy = input.py - input.last_py;
  if (input.down[1]) camera.orbit(-0.3 * dx, 0.3 * dy);
  if (input.down[2]) camera.pan(view, vol.grid, dx / fb[1], dy / fb[1]);
  input.last_px = input.px;
  input.last_py = input.py;
  if (input.scroll != 0) {
    if (ctrl) camera.zoom_by(std::pow(1.1, input.scroll));
    else push_m = std::clamp(push_m + 1e-3 * input.scroll, -0.02, 0.05);
    input.scroll = 0;
  }
}

/// The hand: on the cursor's ray, push_m behind the surface the last frame showed there.
Vec3 Sculpt::steer_hand(const FrameSize& f) {
  const Ray ray = cursor_ray(view, f.fb[0], f.fb[1], input.px, input.py);
  if (img.width == f.rw && img.height == f.rh) {
    const int cx = std::clamp(int(std::lround(input.px * f.rw / f.fb[0])), 0, f.rw - 1);
    const int cy = std::clamp(int(std::lround(input.py * f.rh / f.fb[1])), 0, f.rh - 1);
    const float t = caster->last_depth(cx, cy);
    if (t > 0) hand_t = double(t) + push_m;
  }
  Vec3 hand_world = ray.origin + ray.dir * hand_t;
  // Over the slice views the 3-D view is hidden: a press there moves the target into the
  // pane's plane, and the target stays where it was while the cursor is over them.
  if (const auto t = slice_target()) hand_world = *t;
  else if (slices_shown() && slices.over(input.px, input.py)) hand_world = last_hand_world;
  last_hand_world = hand_world;
  if (input.cursor_seen && mouse) mouse_device->set_hand_target(xf.to_device(hand_world));
  if (input.cursor_seen && o.sim_clock) sim_hand.waypoints.front().pos_m = hand_world;
  return hand_world;
}

}  // namespace isotouch::sculpt::detail
