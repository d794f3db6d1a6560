#include "isotouch/apps/sculpt/app.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <exception>
#include <functional>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <sstream>
#include <iostream>
#include <thread>

#include <unistd.h>

#include "isotouch/sim/coupled_hand_device.h"
#include "isotouch/servo/live_passivity.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/session/edit_session.h"
#include "isotouch/core/exit_codes.h"
#include "isotouch/apps/sculpt/burr.h"
#include "isotouch/apps/sculpt/frame.h"
#include "isotouch/run/haptic_device.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/hri.h"
#include "isotouch/apps/sculpt/input_script.h"
#include "isotouch/session/live_session.h"
#include "isotouch/apps/sculpt/overlay.h"
#include "isotouch/engine/device_memory.h"
#include "isotouch/engine/raycast.h"
#include "isotouch/engine/frame_budget.h"
#include "isotouch/engine/upscale.h"
#include "isotouch/bench/moving_frames.h"
#include "isotouch/bench/scale_quality.h"
#include "isotouch/io/journal_offer.h"
#include "isotouch/io/record.h"
#include "isotouch/run/picture.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/materials/label_volume.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/io/scene.h"
#include "isotouch/session/edit_history.h"
#include "isotouch/session/stop_signal.h"
#include "isotouch/eval/stats.h"
#include "isotouch/apps/sculpt/tools.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/apps/sculpt/window.h"
#include "isotouch/apps/sculpt/scan_input.h"
#include "isotouch/apps/sculpt/background_load.h"
#include "isotouch/apps/sculpt/iso_panel.h"
#include "isotouch/apps/sculpt/slice_views.h"
#include "isotouch/apps/sculpt/still_view.h"

namespace isotouch::sculpt {

struct Carried {
  engine::Volume volume;             ///< as edited (min and max refreshed), or as a dropped file loaded
  std::optional<engine::OrbitCamera> camera;  ///< none: the volume's default
  std::optional<ToolState> tool;     ///< none: the default tool
  std::vector<InputEvent> script;    ///< the script's events after the one that restarted
  std::optional<engine::IsoChoice> choice;  ///< a dropped volume: the isovalue its file chose
};

namespace fs = std::filesystem;
using core::Vec3;
using Clock = std::chrono::steady_clock;

namespace {

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

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

std::string fixed(double v, int p = 1) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(p) << v;
  return s.str();
}

/// What the edit thread hands the frame thread: the voxels of the bricks the applied edits
/// changed, copied into `values` (the edited volume as the picture should show it).
struct PictureFeed {
  std::mutex mu;
  std::condition_variable applied;     // notified after each applied or refused event
  std::vector<float> values;
  std::vector<std::uint32_t> pending;  // bricks changed since the frame last took them
  long brushes_done = 0;               // brushes applied or refused, in submission order
  std::vector<char> brush_changed;     // per brush: it changed some voxel
  long events_done = 0;                // every event applied or refused
  std::string last_error;
};

/// Input state fed by GLFW's callbacks and by the script.
struct Input {
  double px = 0, py = 0;            // cursor, framebuffer pixels
  bool down[3] = {false, false, false};
  double last_px = 0, last_py = 0;  // cursor at the previous frame (drags)
  double scroll = 0;
  struct Key {
    int key;
    bool ctrl, shift;
  };
  std::vector<Key> keys;
  std::vector<std::string> drops;   // files dropped on the window
  bool cursor_seen = false;
};

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

/// The scene to sculpt: the scene file, or a scene made for a volume file.
io::Scene input_scene(const Options& o) {
  const fs::path p(o.input);
  if (p.extension() == ".json") {
    io::Scene sc = io::load_scene(o.input);
    if (o.iso) sc.hri.tau = *o.iso;
    sc.allow_unstable_stiffness = sc.allow_unstable_stiffness || o.allow_unstable_stiffness;
    return sc;
  }
  if (!o.iso) throw std::runtime_error(o.input + ": a volume needs --iso VALUE (the isovalue in the volume's units)");
  if (o.inside != "above" && o.inside != "below")
    throw std::runtime_error("--inside must be \"above\" or \"below\", got \"" + o.inside + "\"");
  std::ostringstream t;
  t << std::setprecision(17) << "{\"name\": \"sculpt\", \"volume\": {\"path\": \"" << fs::absolute(p).string()
    << "\"}, \"isovalue\": " << *o.iso << ", \"inside\": \"" << o.inside << "\"}";
  io::Scene sc = io::parse_scene(t.str(), o.input);
  sc.allow_unstable_stiffness = o.allow_unstable_stiffness;
  return sc;
}

/// The range of a volume's finite voxels, after edits.
void refresh_range(engine::Volume& v) {
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (float x : v.voxels)
    if (std::isfinite(x)) {
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
  if (lo <= hi) {
    v.min_value = lo;
    v.max_value = hi;
  }
}

/// The stats panel's volume line: dims, spacing, orientation.
std::string volume_line(const engine::Volume& v) {
  const auto& d = v.grid.dims;
  const Vec3& s = v.grid.spacing_m;
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]) + ", " + fixed(s.x * 1e3, 2) +
         " x " + fixed(s.y * 1e3, 2) + " x " + fixed(s.z * 1e3, 2) + " mm, " + v.orientation();
}

/// The stats panel's edit-to-haptics median is over the newest this many edits.
constexpr std::size_t kPanelLatencies = 256;

/// The servo's figures for the stats panel; the tick rate is measured over `seconds` since
/// the last refresh.
void refresh_servo(PanelStats& p, const session::LiveStats& st, double seconds) {
  if (seconds > 0) p.servo_rate_hz = double(st.ticks - p.ticks) / seconds;
  p.ticks = st.ticks;
  p.missed_deadlines = st.missed_deadlines;
  p.faults = st.faults;
  if (st.period_error_p99_us >= 0) p.tick_p99_us = st.period_error_p99_us;
  p.tick_p99_beyond = st.period_error_p99_beyond;
  p.passivity = st.passivity ? servo::describe(*st.passivity) : std::string();
  if (!st.edit_to_haptics_ms.empty()) {
    p.edit_to_haptics_last_ms = st.edit_to_haptics_ms.back();
    p.edit_to_haptics_median_ms = eval::median(st.edit_to_haptics_ms);
  }
}

std::string tool_line(const ToolState& t) {
  return std::string(session::to_string(t.kind)) + " r " + fixed(t.radius_m * 1e3) + " mm, strength " + fixed(t.strength, 2);
}


/// What the edit thread does with each applied or refused edit: copies the voxels of the
/// bricks it changed from the session's volume into the feed (the picture's copy).
session::EditListener picture_feeder(PictureFeed& feed, session::EditSession* es) {
  const auto& dims = es->volume().grid.dims;
  const auto nbx = std::uint32_t((dims[0] + 7) / 8), nby = std::uint32_t((dims[1] + 7) / 8);
  return [&feed, es, nbx, nby](const session::EditEvent& e, const session::EditOutcome& out, session::EditSource) {
    using K = session::EditEvent::Kind;
    const std::vector<std::uint32_t>& ids = e.kind == K::kBrush ? out.brush.dirty : out.restored;
    const engine::Volume& v = es->volume();
    const auto& n = v.grid.dims;
    std::lock_guard<std::mutex> lock(feed.mu);
    if (out.error.empty())
      for (std::uint32_t id : ids) {
        const int bx = int(id % nbx), by = int(id / nbx % nby), bz = int(id / (nbx * nby));
        const int x0 = 8 * bx, x1 = std::min(n[0], x0 + 8);
        for (int z = 8 * bz; z < std::min(n[2], 8 * bz + 8); ++z)
          for (int y = 8 * by; y < std::min(n[1], 8 * by + 8); ++y) {
            const std::size_t at = (std::size_t(z) * std::size_t(n[1]) + std::size_t(y)) * std::size_t(n[0]) + std::size_t(x0);
            std::copy(v.voxels.begin() + long(at), v.voxels.begin() + long(at) + (x1 - x0), feed.values.begin() + long(at));
          }
        feed.pending.push_back(id);
      }
    else
      feed.last_error = "edit refused: " + out.error;
    if (!out.history_error.empty()) feed.last_error = "edit applied, undo history dropped: " + out.history_error;
    if (e.kind == K::kBrush) {
      ++feed.brushes_done;
      feed.brush_changed.push_back(out.error.empty() && !ids.empty());
    }
    ++feed.events_done;
    feed.applied.notify_all();
  };
}

/// A dropped file loading in the background: the options of the session it opens.
struct Loading {
  std::string path;
  Options next;
  BackgroundLoad result;
  Clock::time_point since;
  int frame = 0;  // frames drawn when it started
  bool sim_waited = false;  // the simulated clock waited for it once
};

/// The window's size and the ray caster's picture size this frame.
struct FrameSize {
  std::array<int, 2> fb{0, 0};  // framebuffer pixels
  int rw = 0, rh = 0;           // the picture (fb times --render-scale)
  /// The picture at the window's size goes from the caster's buffer straight into the
  /// swapchain image, packed in its byte order (no host copy); scaled, through the host.
  bool direct() const { return rw == fb[0] && rh == fb[1]; }
};

/// The servo alone after a --bench sculpt: its ticks and misses.
struct ServoAlone {
  long ticks = 0, missed = 0;
};

/// One session of the window, from its input to its report: run_sculpt's set-up steps, the
/// frame loop's state and steps, and the figures printed at the end. The members are
/// destroyed in reverse order: the live session (its threads) before the caster, the picture
/// feed and the edits it uses; the overlay before the window, the window before Vulkan, GLFW
/// before the devices the session used.
struct Sculpt {
  Sculpt(const Options& opts, std::ostream& out, std::optional<Options>* next)
      : o(opts), log(out), reopen(next), budget(engine::FrameBudgetOptions{opts.frame_budget_ms}) {}
  ~Sculpt();
  Sculpt(const Sculpt&) = delete;
  Sculpt& operator=(const Sculpt&) = delete;

  // --- set-up, in this order; false: the reason is logged (exit code 1) ---
  bool load_input();
  bool place_probe();
  bool open_window();
  void open_panels();
  bool open_edits();
  void open_journal();
  bool restore_journal();
  session::LiveSessionConfig session_config();
  bool open_device();
  bool start_session(const session::LiveSessionConfig& cfg);
  void keep_display_off_servo_cpu();
  void init_tools();
  // --- the felt tool (burr.h) ---
  void choose_tool();
  servo::HriParams felt_params();
  void fit_felt_tool();
  void watch_drill(const std::vector<sim::TraceRow>& rows, const session::Observed& obs);
  void print_felt_tool();

  // --- the frame loop ---
  void frame_loop();
  bool frame_step();  // false: the loop ends
  double script_now_s() const;
  bool run_script(const std::array<int, 2>& fb, std::vector<std::string>& shots);
  bool script_waits(const InputEvent& ev);
  bool another_bench_round();
  void apply_event(const InputEvent& ev, const std::array<int, 2>& fb, std::vector<std::string>& shots, bool& quit);
  bool take_input(const std::array<int, 2>& fb);
  void handle_key(const Input::Key& k);
  void steer_camera(const std::array<int, 2>& fb);
  Vec3 steer_hand(const FrameSize& f);
  std::optional<Vec3> slice_target();
  bool slices_shown() const;
  void update_slices(const session::Observed& obs, const std::array<int, 2>& fb);
  void compose_slices(std::vector<std::uint32_t>& px, int w, int h);
  void dump_slices(const std::string& dir);
  void apply_tools(const session::Observed& obs);
  long take_edits();
  void render_picture(const session::Observed& obs, const Vec3& hand_world, const FrameSize& f,
                      const std::function<void()>& meanwhile);
  void show(const FrameSize& f, const std::vector<std::string>& shots, long drawn_brushes);
  bool refine_still(const FrameSize& f, bool shot, bool edited);
  void show_band(const FrameSize& f, long drawn_brushes);
  const std::vector<std::uint32_t>& host_picture(const FrameSize& f, bool shot);
  void build_panels();
  void refresh_panel(const session::Observed& obs, std::size_t frames);
  void measure_latency(long drawn_brushes);
  void write_shots(const std::vector<std::string>& shots, const std::array<int, 2>& fb, const std::vector<std::uint32_t>& px);
  void end_frame(const session::Observed& obs, const std::array<int, 2>& fb);
  void refresh_title(const session::Observed& obs, Clock::time_point now);

  // --- tools: save, export, dropped files, the isovalue ---
  engine::Volume edited_volume();
  void save(const std::string& path);
  void export_mesh(const std::string& path);
  void start_load(const std::string& path);
  bool poll_load();
  bool restart_at(double tau);
  void open_at_chosen_isovalue();
  void say_camera();
  void roll(int quarter_turns);
  void say_isovalue(const engine::IsoChoice& c);
  std::shared_ptr<Carried> carry_over(double tau);

  // --- the end: the report ---
  int finish();
  void settle_loads();
  void close_stroke();
  ServoAlone servo_alone(const session::LiveStats& sculpted);
  void stop_session();
  void close_journal();
  void write_last_screenshot();
  void write_window_shot();
  void print_stats(double seconds, const session::LiveStats& st);
  void print_servo(const session::LiveStats& st);
  void print_device();
  void print_verdicts(const session::LiveStats& sculpted, const ServoAlone& alone);
  void cut_by_material();
  void print_floor();

  const Options& o;
  std::ostream& log;
  std::optional<Options>* reopen;

  // The input.
  io::Scene scene;
  engine::Volume vol;
  std::vector<InputEvent> script;
  fs::path shot_dir;
  // The device: the mouse-coupled simulated probe, or one from --haptic (opened just before
  // the servo starts: an emulator's hand path and a device's watchdog start with the link).
  servo::WorkspaceTransform xf;  // as `isotouch run`: the device's origin at the grid's centre
  CameraControl camera;
  engine::CameraView view;
  Vec3 start_world;
  std::optional<sim::CoupledHandDevice> mouse_device;
  bool mouse = true;
  run::HapticDevice haptic;
  // The window and Vulkan.
  struct GlfwUp {
    bool up = false;
    ~GlfwUp() {
      if (up) shutdown_glfw();
    }
  } glfw;
  std::unique_ptr<engine::VulkanContext> vk;
  std::unique_ptr<Window> window;
  servo::PeerOffCpu display_off;  // the X server's threads kept off the servo's CPU
  Input input;
#if ISOTOUCH_WITH_IMGUI
  std::unique_ptr<Overlay> panels;  // the tool and stats panels, drawn over the picture
#endif
  // The session: edits (CPU brushes: the GPU queue belongs to the window's thread), the
  // picture and the servo.
  session::LiveFieldOptions live;
  std::unique_ptr<session::EditSession> edits;
  io::OpenedJournal journal;  // the edit journal (off: null) and the edits it restores; outlives the session
  std::uint32_t volume_crc = 0;  // io::volume_crc32 of the volume as read: the journal's key
  servo::TripleBuffer<core::SampleField> buffer;
  std::optional<servo::HriRenderer> renderer;
  std::optional<FeltTool> felt;  // what the servo ticks: the renderer with the tool's radius
  DrillWatch drill;
  double felt_m = 0;            // the radius the servo is asked to feel [m] (0: the point)
  long last_watched_tick = -1;  // real time: the last tick DrillWatch saw
  PictureFeed feed;
  std::unique_ptr<engine::RayCaster> caster;
  std::unique_ptr<session::LiveSession> session;
  // The simulated clock: the probe's device, stepped by the frame loop's ticks toward the
  // hand (held still within a frame, as the mouse's coupling holds it within a tick).
  std::optional<sim::SimDevice> sim_device;
  sim::TouchScript sim_hand;
  session::SimulatedRun sim_run;
  long sim_ticks_per_frame = 1;
  double sim_frame_s = 0;

  // The frame loop's state.
  ToolState tool;
  IsoControl iso_ctl;
  // The slice views (slice_views.h): the edits they show so far, whether the left button is
  // on a pane (moving the probe's target, not the tool), the HIP they go through.
  SliceViews slices;
  long slice_edits = 0;
  bool slice_drag = false;
  bool inset_on = false;
  Vec3 slice_hip_m;
  std::vector<double> slice_ms;  // each time the slice views were computed again
  Vec3 last_hand_world;  // the hand's target last frame
  std::optional<std::pair<int, double>> press_normal;  // a press on a pane: its normal axis and plane index, kept while held
  std::optional<engine::IsoChoice> chosen;  // the isovalue chosen for a volume without --iso
  PanelStats panel;
  Clock::time_point panel_refreshed;
  Stroke stroke;
  engine::RaycastStyle style;
  bool overlay = true;
  double push_m = 5e-3;  // the hand this far behind the surface under the cursor
  double hand_t = 0;     // hand depth along the cursor ray [m]
  double unit = 0;       // the probe glyphs' size unit
  std::vector<double> march_ms, shade_ms, overlay_ms;
  std::vector<double> full_march_ms, full_shade_ms, full_overlay_ms;  // frames drawn whole
  std::vector<double> full_render_ms, full_present_ms;
  std::vector<double> frame_ms, render_ms, present_ms, latency_ms, update_ms;
  std::vector<double> frame_full_ms, frame_reused_ms;  // frames whose picture was drawn whole / reused
  std::vector<double> frame_band_ms;                   // frames drawing a band of a still view (StillView)
  struct WholeFrame {
    engine::CameraView view;
    int width, height;  // rendered [pixels]
  };
  std::vector<WholeFrame> full_views;  // --bench: the frames drawn whole (print_floor)
  std::vector<Clock::time_point> brush_submitted;  // per submitted brush
  long brushes_measured = 0;
  long events_submitted = 0;
  std::size_t next_event = 0;
  int wait_frames = 0;
  bool bench_rounds = false;  // the built-in bench script: its quit repeats the rounds until --bench-ticks
  long bench_rounds_run = 0;
  // The script's clock (its waits' timeouts): simulated time on the simulated clock.
  Clock::time_point t_wall0;
  double wait_since = 0;
  std::size_t shown_at_wait = 0;  // brushes that changed the picture when the wait began
  bool waiting = false;
  int code = 0;
  engine::RaycastImage img;
  std::vector<std::uint32_t> upscaled;
  std::array<int, 2> last_fb{0, 0};
  engine::FrameBudget budget;           // the moving view's scale (--frame-budget-ms)
  engine::OrbitCamera last_cam;         // the camera of the last frame, to see the view move
  bool moving_now = false;              // this frame's view moves (picture_scale)
  sculpt::StillView still;              // a still view refined over frames after moving ones
  std::vector<std::uint32_t> band_px;   // the picture a band frame shows (window size, RGBA)
  bool band_frame = false;              // this frame drew a band
  double band_ms = 0;                   // its band's render and copy into the window's picture [ms]
  long refinements = 0, refinements_done = 0, refined_reused = 0;
  bool check_reuse = false;             // the last band was drawn: the next render() should reuse it
  Clock::time_point frame_began;        // this frame's start
  Clock::time_point refine_t0;          // the first band's frame began (the view stopped)
  std::vector<double> refined_ms;       // each refinement: its first band to the frame after its last
  double picture_scale(const std::array<int, 2>& fb, bool shot);
  void print_moving_frames();
  int frame = 0;
  Clock::time_point last_frame;
  std::string status;
  std::string export_path, save_path;
  // Dropped files load one at a time on a background thread while this session goes on (the
  // Stats panel shows the progress); one that loads ends this session and the next starts on
  // it; one that cannot be read shows its error and the session keeps its volume.
  std::optional<Loading> loading;
  std::deque<std::string> drop_queue;
  bool restarting = false;  // the script goes on in the next session
  Clock::time_point t_start;
};

Sculpt::~Sculpt() {
#if ISOTOUCH_WITH_IMGUI
  g_panels = nullptr;
#endif
  if (g_input == &input) g_input = nullptr;
}

// --- set-up ------------------------------------------------------------------------------

/// --save and --export must name a format they write (the format is taken from the name).
/// @throws std::runtime_error naming the option and the path.
void check_output_names(const Options& o) {
  if (!o.save_path.empty() && !io::volume_writable(o.save_path))
    throw std::runtime_error("--save " + o.save_path +
                             ": the name must end in .vdb, .mha, .nrrd, .nii or .nii.gz (the format is taken from it)");
  if (!o.export_path.empty() && io::mesh_format(o.export_path).empty())
    throw std::runtime_error("--export " + o.export_path +
                             ": the name must end in .stl, .obj or .ply (the format is taken from it)");
}

/// The scene, the volume and the script.
bool Sculpt::load_input() {
  try {
    if (o.carried) script = o.carried->script;
    else if (!o.script.empty()) script = load_input_script(o.script);
    else if (o.bench) {
      script = parse_input_script(bench_script_text(), "the built-in bench script");
      bench_rounds = true;
    }
    if (!o.record.empty() && fs::path(o.input).extension() != ".json")
      throw std::runtime_error("--record needs a scene file (the recording names it), got the volume " + o.input);
    check_output_names(o);
    if (o.iso || o.carried || is_scene_path(o.input)) {
      scene = input_scene(o);
      vol = o.carried ? o.carried->volume : run::load_scene_volume(scene);
    } else {
      open_at_chosen_isovalue();
    }
    if (o.carried && o.carried->choice) say_isovalue(*o.carried->choice);
    if (!(scene.hri.tau > vol.min_value && scene.hri.tau < vol.max_value))
      throw std::runtime_error(o.input + ": isovalue " + fixed(scene.hri.tau, 3) + " is outside the range [" +
                               fixed(vol.min_value, 3) + ", " + fixed(vol.max_value, 3) + "] of " + vol.path +
                               ": there is no isosurface");
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << "\n";
    return false;
  }
  shot_dir = o.screenshot.empty() ? fs::path(".") : fs::path(o.screenshot).parent_path();
  return true;
}

/// The camera, and the mouse's probe at rest just outside the volume's box in front of it.
bool Sculpt::place_probe() {
  xf.scale = scene.workspace_scale;
  xf.translation_m = vol.grid.centre_m();
  camera.cam = o.carried && o.carried->camera ? *o.carried->camera : run::default_camera(vol);
  view = engine::orbit_view(vol.grid, vol.direction, camera.cam);
  say_camera();
  start_world = vol.grid.centre_m() - view.forward * (0.6 * norm(vol.grid.extent_m()));
  mouse_device.emplace(scene.device, xf.to_device(start_world), 1.0 / scene.hri.rate_hz);
  mouse = o.haptic == "mouse";
  if (o.sim_clock && !mouse) {
    log << "isotouch-sculpt: --sim-clock runs the mouse probe on a simulated clock; --haptic " << o.haptic
        << " is a device in real time (leave out one of them)\n";
    return false;
  }
  return true;
}

/// GLFW, the Vulkan context with a swapchain, the window and its input callbacks.
bool Sculpt::open_window() {
  auto exts = init_glfw();
  if (!exts) {
    log << "isotouch-sculpt: " << exts.error << "\n";
    return false;
  }
  glfw.up = true;
  engine::ContextOptions co;
  co.device = o.device;
  co.validation = o.validation;
  co.instance_extensions = *exts.value;
  co.swapchain = true;
  auto ctx = engine::VulkanContext::create(co);
  if (!ctx) {
    log << "isotouch-sculpt: " << ctx.error << "\n";
    return false;
  }
  vk = std::move(*ctx.value);
  const PresentPath path = o.present == "shm" ? PresentPath::kShm
                            : o.present == "swapchain" ? PresentPath::kSwapchain
                                                       : PresentPath::kAuto;
  auto win = Window::create(*vk, o.width, o.height, "isotouch-sculpt: " + scene.name, path);
  if (!win) {
    log << "isotouch-sculpt: " << win.error << "\n";
    return false;
  }
  window = std::move(*win.value);
  g_input = &input;
  if (!o.sim_clock) {  // on the simulated clock the script is the only input
    glfwSetCursorPosCallback(window->handle(), on_cursor);
    glfwSetMouseButtonCallback(window->handle(), on_button);
    glfwSetScrollCallback(window->handle(), on_scroll);
    glfwSetKeyCallback(window->handle(), on_key);
    glfwSetDropCallback(window->handle(), on_drop);
    glfwSetCharCallback(window->handle(), on_char);
  }
  return true;
}

/// The Dear ImGui panels (a build with them, unless --no-overlay); one that cannot start is a note.
void Sculpt::open_panels() {
#if ISOTOUCH_WITH_IMGUI
  if (o.overlay) {
    auto made = Overlay::create(*vk, *window);
    if (made) {
      panels = std::move(*made.value);
      log << "overlay  " << Overlay::version() << "\n";
    } else {
      log << "overlay  not drawn: " << made.error << "\n";
    }
  }
  g_panels = panels.get();
#endif
}

/// A labelled scene: the Sculptor removes each material at its own rate and density scale and
/// never changes a critical one (what `isotouch run` does, run::material_cut).
/// @throws materials::MaterialError, engine::VolumeError as materials::load_label_volume.
void Sculpt::cut_by_material() {
  const materials::LabelVolume lv = materials::load_label_volume(scene.materials, vol);
  edits->sculptor().set_material_cut(run::material_cut(lv));
  log << "sculpt   cuts by material (" << lv.source << "):";
  for (std::size_t i = 0; i < lv.materials.size(); ++i)
    log << (i ? ", " : " ") << lv.materials[i].name << (lv.materials[i].critical ? " (critical: never changed)" : "");
  log << "\n";
  for (const std::string& n : lv.notes) log << "         note: " << n << "\n";
}

/// The edit session on the volume, its first snapshot, the renderer, and the ray caster on the
/// raw volume at the scene's isovalue (what `isotouch render` draws).
bool Sculpt::open_edits() {
  live.passes = run::scene_passes(scene);
  live.iso = core::Isosurface{scene.hri.tau, scene.hri.inside};
  live.background = float(live.iso.outside_value(vol.min_value, vol.max_value));
  live.format = run::scene_sample_format(scene);
  try {
    edits = std::make_unique<session::EditSession>(engine::Volume(vol), nullptr, live, scene.edits.history_limit_mib);
    if (scene.materials.present) cut_by_material();
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << o.input << ": " << e.what() << "\n";
    return false;
  }
  buffer.publish(edits->current());
  choose_tool();
  renderer.emplace(felt_params());
  felt.emplace(*renderer);
  if (!o.record.empty()) felt->fix();  // the recording replays with one tool (felt_params)
  feed.values = vol.voxels;
  auto rc = engine::RayCaster::create(*vk, run::scene_raycast_field(scene, vol));
  if (!rc) {
    log << "isotouch-sculpt: " << rc.error << "\n";
    return false;
  }
  caster = std::move(*rc.value);
  return true;
}

/// The edit journal of the volume as read (journal_offer.h), and what a killed session left
/// in it, as --restore says. A volume carried over from an isovalue change is no file's: no
/// journal (the log says so).
void Sculpt::open_journal() {
  if (!o.journal) return;
  if (o.carried) {
    log << "journal  off: the volume carried over from the isovalue change is not its file's (Ctrl+S saves it)\n";
    return;
  }
  volume_crc = io::volume_crc32(vol);
  // A recording replays from the volume's file: edits restored before it started would not be in it.
  if (!o.record.empty())
    log << "journal  --record: a journal left on this volume is not restored (the recording replays from the file)\n";
  const io::RestoreChoice choice = o.record.empty() ? io::restore_choice(o.restore) : io::RestoreChoice::kNo;
  journal = io::open_journal("sculpt", volume_crc, choice, log, std::cin, ::isatty(STDIN_FILENO) == 1);
}

/// Applies the journal's restored edits to the edit session and the picture, then starts
/// the journal afresh with them. False: an edit could not be applied (logged; the journal
/// file is untouched).
bool Sculpt::restore_journal() {
  if (!journal.journal) return true;
  try {
    io::apply_restored(*edits, journal.restore, &buffer);
    if (!journal.restore.empty()) {
      feed.values = edits->volume().voxels;
      for (std::uint32_t id = 0; id < std::uint32_t(session::brick_total(vol.grid)); ++id) feed.pending.push_back(id);
      log << "journal  restored " << journal.restore.size() << " edits\n";
    }
    io::Recording header;
    header.scene_path = fs::absolute(o.input).string();
    header.rate_hz = scene.hri.rate_hz;
    header.volume_crc32 = volume_crc;
    journal.journal->start(header, journal.restore);
    journal.restore = {};  // applied and in the new journal
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << (journal.journal ? journal.journal->path() : std::string()) << ": " << e.what() << "\n";
    return false;
  }
  log << "journal  " << journal.journal->path() << "\n";
  return true;
}

/// The live session's configuration: the servo, the recording, the picture's feed.
session::LiveSessionConfig Sculpt::session_config() {
  session::LiveSessionConfig cfg;
  cfg.servo.rate_hz = scene.hri.rate_hz;
  cfg.servo.force_limit_n = scene.hri.force_limit_n;  // the gate: min(scene, device)
  cfg.servo.passivity_control = scene.passivity_control;
  cfg.servo.sched_fifo = o.sched_fifo;
  cfg.servo.pin_cpu = o.sched_fifo;
  cfg.servo.lock_memory = o.sched_fifo;
  cfg.servo.world_T_device = xf;
  cfg.record_path = o.record;
  if (!o.record.empty()) {
    cfg.record_header.scene_path = fs::absolute(scene.file).string();
    std::ifstream in(scene.file, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    cfg.record_header.scene_text = scene_text_with_tool(text.str(), renderer->params().tool_radius_m, scene.file);
    cfg.record_header.rate_hz = scene.hri.rate_hz;
    cfg.record_header.volume_crc32 = io::volume_crc32(vol);
    // This app's edit session, whatever the scene's "edits" say: replay builds the same one.
    cfg.record_header.edit_session =
        io::RecordedEditSession{edits->sculptor().on_gpu(), scene.edits.history_limit_mib, renderer->params().edit_period_s};
  }
  cfg.on_applied = picture_feeder(feed, edits.get());
  if (io::Journal* j = journal.journal.get())
    cfg.on_applied = [j, feeder = std::move(cfg.on_applied)](const session::EditEvent& e, const session::EditOutcome& out,
                                                              session::EditSource source) {
      if (out.error.empty()) j->append(e);  // what the recording records: the edits applied
      feeder(e, out, source);
    };
  return cfg;
}

/// A --haptic device (the mouse's needs nothing more).
bool Sculpt::open_device() {
  if (mouse) return true;
  try {
    run::DeviceSetup ds;
    ds.scene = &scene;
    ds.volume = &vol;
    ds.hri = scene.hri;
    ds.world_T_device = xf;
    ds.start_world_m = start_world;
    haptic = run::open_haptic_device(o.haptic, ds, o.sched_fifo ? 70 : 0);
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << " (or mouse, the default)\n";
    return false;
  }
  log << "device   " << haptic.description << "\n";
  if (haptic.report && !haptic.report->realtime_note().empty()) log << "device   " << haptic.report->realtime_note() << "\n";
  return true;
}

/// The live session, started on its own threads, or stepped by the frame loop on the simulated clock.
bool Sculpt::start_session(const session::LiveSessionConfig& cfg) {
  servo::HapticDeviceIO& device = mouse ? static_cast<servo::HapticDeviceIO&>(*mouse_device) : *haptic.io;
  try {
    if (o.sim_clock) session = std::make_unique<session::LiveSession>(edits.get(), buffer, *felt, cfg);
    else session = std::make_unique<session::LiveSession>(*edits, buffer, *felt, device, cfg);
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << "\n";
    return false;
  }
  sim_device.emplace(scene.device, xf.to_device(start_world));
  sim_hand.waypoints = {{0.0, start_world}};
  sim_run.device = &*sim_device;
  sim_run.script = &sim_hand;
  sim_run.world_T_device = xf;
  sim_ticks_per_frame = std::max(1L, std::lround(o.sim_frame_ms * 1e-3 * scene.hri.rate_hz));
  sim_frame_s = double(sim_ticks_per_frame) / scene.hri.rate_hz;
  if (!o.sim_clock) {
    // The X server's guard forked before the servo runs (keep_display_off_servo_cpu).
    if (o.display_off_servo_cpu && o.sched_fifo) (void)display_off.start_guard();
    const std::string note = session->start();
    if (!note.empty()) log << "servo    " << note << "\n";
    if (o.display_off_servo_cpu) keep_display_off_servo_cpu();
  }
  log << "sculpt   " << scene.name << ": " << vol.grid.dims[0] << "x" << vol.grid.dims[1] << "x" << vol.grid.dims[2]
      << " voxels, isovalue " << scene.hri.tau << ", servo " << scene.hri.rate_hz << " Hz, device " << vk->info().name
      << ", present mode " << window->present_mode() << "\n";
  if (!window->present_note().empty()) log << "sculpt   " << window->present_note() << "\n";
  if (o.sim_clock)
    log << "sculpt   simulated clock: " << sim_ticks_per_frame << " servo ticks (" << fixed(sim_frame_s * 1e3, 2)
        << " ms) per frame, on the window's thread\n";
  return true;
}

/// The X server off the servo's CPU, and this thread presenting from another one: both copy
/// a software-presented frame through the X socket in system calls that hold a CPU for
/// milliseconds, which the servo thread, woken on time, would wait behind.
void Sculpt::keep_display_off_servo_cpu() {
  const int cpu = session->servo_thread()->pinned_cpu();
  if (cpu < 0) return;  // not pinned: nothing to keep off
  if (const std::string e = window->keep_present_off_cpu(cpu); !e.empty()) log << "servo    " << e << "\n";
  const int fd = window->display_fd();
  if (fd < 0) return;
  std::string why;
  const pid_t pid = servo::peer_pid(fd, why);
  const std::string name = pid > 0 ? servo::process_name(pid) : "";
  if (pid > 0 && !servo::is_x_server(name))
    why = "the display socket's owner " + name + " (pid " + std::to_string(pid) + ") is not an X server";
  if (why.empty()) why = display_off.keep_off(pid, cpu);
  if (!why.empty())
    log << "servo    display server left on CPU " << cpu << ": " << why << "\n";
  else if (display_off.threads_moved() == 0)
    log << "servo    display server " << name << " (pid " << pid << ") has no thread on CPU " << cpu
        << " that could move\n";
  else
    log << "servo    display server " << name << " (pid " << pid << ", " << display_off.threads_moved() << (display_off.threads_moved() == 1 ? " thread" : " threads")
        << ") kept off CPU " << cpu << ", the servo's; given back at exit, or by guard process "
        << display_off.guard_pid() << " if this one dies\n";
}

/// The tool (carried over or sized to the voxels), the panels' fixed lines, the loop's clocks.
void Sculpt::init_tools() {
  print_felt_tool();
  iso_ctl = IsoControl{scene.hri.tau, vol.min_value, vol.max_value, false};
  fill_iso_panel(iso_ctl, vol, chosen);
  slices.open(vol, live.iso, chosen ? chosen->hounsfield : engine::is_ct_hounsfield(vol, ""));
  slices.control().shown = o.slices;
  panel.servo_target_hz = scene.hri.rate_hz;
  panel.volume = volume_line(vol);
  panel_refreshed = Clock::now();
  style.tile_starts = o.tile_starts;
  hand_t = norm(vol.grid.centre_m() - view.eye);
  last_hand_world = start_world;
  unit = run::probe_size_m(vol.grid);
  wait_frames = script.empty() ? 0 : script[0].after_frames;
  t_wall0 = Clock::now();
  last_frame = Clock::now();
  export_path = o.export_path.empty() ? (fs::path(o.input).stem().string() + "-sculpted.stl") : o.export_path;
  save_path = o.save_path.empty() ? (fs::path(o.input).stem().string() + "-sculpted.vdb") : o.save_path;
}

// --- the felt tool: the carve or drill brush is felt as a sphere of its radius (burr.h) ----

/// A radius as a recording's scene text gives it back to replay (radius_mm, parsed): the
/// same bits, so that a recorded session replays identically.
double as_recorded(double radius_m) { return 1e-3 * (1e3 * radius_m); }

/// The tool: carried over, or the scene's tool radius where it gives one, else sized to
/// the voxels.
void Sculpt::choose_tool() {
  if (o.carried && o.carried->tool) tool = *o.carried->tool;
  tool.targets = session::default_targets(vol, live.iso);
  if (o.carried && o.carried->tool) return;
  const double sp = std::max({vol.grid.spacing_m.x, vol.grid.spacing_m.y, vol.grid.spacing_m.z});
  tool.radius_m = scene.hri.tool_radius_m > 0 ? scene.hri.tool_radius_m : std::max(4e-3, 2.5 * sp);
}

/// The scene's servo with the tool's felt radius; the point where the scene keeps it or
/// renders what the sphere does not (the paper variant, friction, force shading).
servo::HriParams Sculpt::felt_params() {
  servo::HriParams p = scene.hri;
  const bool sphere_ok = p.variant == servo::Variant::kRobust && !p.friction.any() && !p.force_shading && !scene.point_probe;
  felt_m = sphere_ok ? as_recorded(felt_radius_m(tool, o.point_probe)) : 0.0;
  p.tool_radius_m = felt_m;
  if (!sphere_ok) felt_m = -1;  // never a sphere in this session
  // The app's brushes come once a frame: an edit's material took a frame to cut.
  if (o.sim_clock) p.edit_period_s = double(std::max(1L, std::lround(o.sim_frame_ms * 1e-3 * p.rate_hz))) / p.rate_hz;
  return p;
}

/// Each frame: the servo feels the tool's radius (a recorded session the one it began
/// with) and the brush fits what is felt.
void Sculpt::fit_felt_tool() {
  if (felt_m >= 0 && !felt->fixed()) {
    felt_m = as_recorded(felt_radius_m(tool, o.point_probe));
    felt->want(felt_m);
  }
  fit_brush_to_felt_tool(tool, std::max(0.0, felt_m), cut_margin_m(vol));
}

/// The ticks since the last frame for the drill's figures: every tick on the simulated
/// clock, else the frame's observed one.
void Sculpt::watch_drill(const std::vector<sim::TraceRow>& rows, const session::Observed& obs) {
  std::vector<TickSample> ticks;
  for (const sim::TraceRow& r : rows) ticks.push_back({r.t_s, r.force_n, r.vhip_m, r.contact});
  if (!o.sim_clock && obs.tick > last_watched_tick) {
    ticks.push_back({double(obs.tick) / scene.hri.rate_hz, obs.force_n, obs.vhip_m, obs.contact});
    last_watched_tick = obs.tick;
  }
  drill.ticks(ticks);
}

void Sculpt::print_felt_tool() {
  const double margin = cut_margin_m(vol);
  if (felt_m < 0)
    log << "sculpt   tool felt as the point: the scene keeps it (servo.tool.point, the paper variant, friction or force shading)\n";
  else if (o.point_probe)
    log << "sculpt   tool felt as the point (--point-probe); the brush cuts its own radius around it\n";
  else
    log << "sculpt   tool felt as a sphere of the carve or drill brush's radius (" << fixed(felt_m * 1e3, 2)
        << " mm now; add and smooth: the point); the brush cuts to its surface and fades over "
        << fixed(margin * 1e3, 2) << " mm (half a voxel) beyond it\n";
  if (felt->fixed() && felt_m >= 0)
    log << "sculpt   --record: the tool stays as felt now for the whole session (the recording replays with one "
           "tool); the brush follows radius changes\n";
}

// --- the frame loop ------------------------------------------------------------------------

void Sculpt::frame_loop() {
  t_start = Clock::now();
  while (!window->should_close() && session::stop_signal() == 0) {
    if (o.frames > 0 && frame >= o.frames) break;
    if (!frame_step()) break;
  }
}

/// One frame: the script, the input, the hand, the tools, the edits, the picture, the window.
bool Sculpt::frame_step() {
  frame_began = Clock::now();
  glfwPollEvents();
  FrameSize f;
  f.fb = window->framebuffer_size();
  if (f.fb[0] == 0 || f.fb[1] == 0) {  // minimised: the session keeps running, nothing is drawn
    glfwWaitEventsTimeout(0.05);
    // No frame: the next one's time (a refinement band's frame among them) starts here, not
    // before the window was minimised.
    last_frame = Clock::now();
    return true;
  }
  std::vector<std::string> shots;
  if (run_script(f.fb, shots)) return false;
  if (wait_frames > 0 && !waiting) --wait_frames;
  if (take_input(f.fb)) return false;
  view = engine::orbit_view(vol.grid, vol.direction, camera.cam);
  // At most one storage binding of 4-byte pixels: a larger window is drawn at a lower scale.
  const double fit = std::sqrt(double(vk->max_binding_bytes() / 4) / (double(f.fb[0]) * double(f.fb[1])));
  const double scale = picture_scale(f.fb, !shots.empty());
  const auto pixels = [&](int n) {
    return std::max(1, int(fit < scale ? std::floor(n * fit) : std::round(n * scale)));
  };
  f.rw = pixels(f.fb[0]);
  f.rh = pixels(f.fb[1]);
  const Vec3 hand_world = steer_hand(f);
  const session::Observed obs = session->observe();
  apply_tools(obs);
  const std::size_t updates = update_ms.size();
  const long drawn_brushes = take_edits();
  band_frame = refine_still(f, !shots.empty(), update_ms.size() != updates);
  if (band_frame) {
    update_slices(obs, f.fb);
    show_band(f, drawn_brushes);
    end_frame(obs, f.fb);
    return true;
  }
  // The slice views are computed while the device draws (on a CPU device its threads hold
  // the cores, and this thread would wait for them idle).
  render_picture(obs, hand_world, f, [&] { update_slices(obs, f.fb); });
  if (check_reuse) refined_reused += img.reused;
  show(f, shots, drawn_brushes);
  if (check_reuse) refined_ms.push_back(ms_since(refine_t0));
  check_reuse = false;
  end_frame(obs, f.fb);
  return true;
}

/// The part of a frame's render that scales with its pixels [ms]: the march and shade passes
/// (device timestamps), or the whole render where there are none.
static double scaling_ms(const engine::RaycastImage& img, double render_ms) {
  return img.march_ms >= 0 ? std::min(render_ms, img.march_ms + std::max(0.0, img.shade_ms)) : render_ms;
}

static bool same_vec(const Vec3& a, const Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
static bool same_camera(const engine::OrbitCamera& a, const engine::OrbitCamera& b) {
  const bool same_target = a.target_m.has_value() == b.target_m.has_value() && (!a.target_m || same_vec(*a.target_m, *b.target_m));
  return a.azimuth_deg == b.azimuth_deg && a.elevation_deg == b.elevation_deg && a.distance_m == b.distance_m &&
         a.zoom == b.zoom && a.fov_y_deg == b.fov_y_deg && same_target && same_vec(a.up_phys, b.up_phys) &&
         same_vec(a.front_phys, b.front_phys);
}

/// This frame's picture scale: while the view moves (camera or window size), what the frame
/// budget allows (at most --render-scale); still, --render-scale. At --render-scale always:
/// the built-in bench's rounds (their verdicts measure the renderer), a frame a script takes a
/// screenshot of, and the simulated clock (a wall-clock budget would make its pictures vary).
double Sculpt::picture_scale(const std::array<int, 2>& fb, bool shot) {
  const bool moving = frame > 0 && (!same_camera(camera.cam, last_cam) || fb != last_fb);
  last_cam = camera.cam;
  moving_now = moving;
  if (!moving || o.frame_budget_ms <= 0 || bench_rounds || shot || o.sim_clock) return o.render_scale;
  return std::min(o.render_scale, budget.moving_scale());
}

/// A still view after moving frames drawn smaller: this frame draws the next band of its
/// full-resolution picture (StillView) within the frame budget. False: the frame is drawn by
/// render() as ever (a moving view, an edit shown at once, a screenshot, the bench's rounds,
/// the simulated clock, no budget, or the picture already at this size).
bool Sculpt::refine_still(const FrameSize& f, bool shot, bool edited) {
  if (o.frame_budget_ms <= 0 || moving_now || shot || edited || bench_rounds || o.sim_clock) {
    still.stop();
    return false;
  }
  if (!still.active()) {
    if (check_reuse || img.reused || !still.start(img, f.rw, f.rh, budget)) return false;
    ++refinements;
    refine_t0 = frame_began;
  }
  caster->set_bgra(f.direct() && window->bgra());  // as the render() after the bands: it reuses them
  const auto r0 = Clock::now();
  still.band(*caster, view, style, f.fb, band_px);
  band_ms = ms_since(r0);
  render_ms.push_back(band_ms);
  img = engine::RaycastImage{};  // the caster's buffers no longer hold that frame (steer_hand reads their depth)
  if (still.last_band()) {
    ++refinements_done;
    check_reuse = true;
  }
  return true;
}

/// A band frame's picture into the window with the panels.
void Sculpt::show_band(const FrameSize& f, long drawn_brushes) {
  const auto p0 = Clock::now();
  build_panels();
  const bool shown = window->present(band_px, f.fb[0], f.fb[1]);
  present_ms.push_back(ms_since(p0));
  if (shown) measure_latency(drawn_brushes);
}

/// --bench: frames drawn whole while the view orbits, at the frame budget's scale, after the
/// rounds (the session stopped), at the window's last size from the last camera; then the
/// picture error of each upscale at fixed scales on three of the orbit's views.
void Sculpt::print_moving_frames() {
  if (o.frame_budget_ms <= 0 || last_fb[0] <= 0 || last_fb[1] <= 0) return;
  bench::MovingFramesOptions mo;
  mo.budget_ms = o.frame_budget_ms;
  caster->set_in_place(false);
  // At most one storage binding of 4-byte pixels, as frame_step draws.
  const double fit = std::sqrt(double(vk->max_binding_bytes() / 4) / (double(last_fb[0]) * double(last_fb[1])));
  try {
    const bench::MovingFramesResult r = bench::run_moving_frames(*caster, vol.grid, vol.direction, camera.cam, style,
                                                                 last_fb[0], last_fb[1], mo, std::min(1.0, fit));
    bench::print_moving_frames(log, r, mo, last_fb[0], last_fb[1]);
    // What scale a picture quality needs: the error at fixed scales (each upscale).
    const int views = 3;
    std::vector<double> scales;
    for (double s : {0.5, 0.625, 0.75, 0.875})
      if (s <= fit) scales.push_back(s);
    bench::print_scale_quality(
        log, bench::scale_quality(*caster, vol.grid, vol.direction, camera.cam, style, last_fb[0], last_fb[1], mo, scales, views),
        views);
  } catch (const std::exception& e) {
    log << "moving   not measured: " << e.what() << "\n";
  }
}

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

/// With the mouse probe and the slice views shown, the left button on a pane moves the
/// probe's target to the voxel under the cursor in that pane's plane (said once a press).
std::optional<Vec3> Sculpt::slice_target() {
  const bool was = slice_drag;
  slice_drag = false;
  if (!input.down[0]) press_normal.reset();
  if (!slices_shown() || !input.down[0] || !input.cursor_seen || !(mouse || o.sim_clock)) return std::nullopt;
  auto h = slices.hit(input.px, input.py);
  if (!h) return std::nullopt;
  slice_drag = true;
  // The pane's plane as pressed: the slices follow the probe, which must not move the plane
  // it is dragged in.
  const int normal = slices.normal_axis(h->first);
  if (!was || !press_normal || press_normal->first != normal) press_normal = std::make_pair(normal, h->second[normal]);
  double idx[3] = {h->second.x, h->second.y, h->second.z};
  idx[normal] = press_normal->second;
  h->second = Vec3{idx[0], idx[1], idx[2]};
  const Vec3 target = vol.grid.to_world(h->second);
  if (!was) {
    const Vec3 p = vol.to_physical(target) * 1e3;
    log << "slices   target from the " << to_string(h->first) << " view: index (" << fixed(h->second.x, 2) << ", "
        << fixed(h->second.y, 2) << ", " << fixed(h->second.z, 2) << "), physical (" << fixed(p.x, 2) << ", "
        << fixed(p.y, 2) << ", " << fixed(p.z, 2) << ") mm\n";
  }
  return target;
}

bool Sculpt::slices_shown() const { return o.slices && overlay && slices.control().shown; }

/// The slice views through the HIP (computed again only when what they show changed), into
/// the window's inset; hidden with the overlay (H).
void Sculpt::update_slices(const session::Observed& obs, const std::array<int, 2>& fb) {
  if (!slices_shown()) {
    if (inset_on) window->set_inset({}, 0, 0, 0, 0);
    inset_on = false;
    return;
  }
  slice_hip_m = obs.tick >= 0 ? obs.hip_m : start_world;
  const Vec3 proxy = obs.tick >= 0 ? obs.vhip_m : start_world;
  bool changed = false;
  const auto t0 = Clock::now();
  {
    std::lock_guard<std::mutex> lock(feed.mu);
    changed = slices.update(feed.values, vol.grid.to_index(slice_hip_m), vol.grid.to_index(proxy), slice_edits, fb);
  }
  if (changed) slice_ms.push_back(ms_since(t0));
  if (changed || !inset_on) window->set_inset(slices.column(), slices.column_x(), 0, slices.size(), 3 * slices.size());
  inset_on = true;
}

void Sculpt::compose_slices(std::vector<std::uint32_t>& px, int w, int h) {
  if (w == slices.column_x() + slices.size()) slices.compose(px, w, h);
}

/// --slices-png: the three slices (one pixel per voxel) and slices.json into `dir`.
void Sculpt::dump_slices(const std::string& dir) {
  slices.dump(dir, vol.to_physical(slice_hip_m) * 1e3);
  log << "sculpt   slices " << dir << "\n";
}

/// Tools: one application per frame while the left button is held and the probe touches;
/// on the simulated clock, this frame's ticks (the edits submitted so far are applied after
/// the first of them; on_applied feeds the picture on this thread).
void Sculpt::apply_tools(const session::Observed& obs) {
  const auto now = Clock::now();
  const double dt_s = o.sim_clock ? sim_frame_s : std::chrono::duration<double>(now - last_frame).count();
  fit_felt_tool();
  const bool tool_down = input.down[0] && !slice_drag;
  drill.press(tool_down && tool.kind == session::BrushKind::kDrill, felt->applied_m() > 0 ? felt->applied_m() : tool.radius_m,
              tool.radius_m + tool.cut_margin_m, [this] { return edited_volume(); });
  std::vector<session::EditEvent> evs;
  stroke.frame(tool_down, obs.contact, tool, obs.vhip_m, norm(obs.force_n), dt_s, evs);
  for (const session::EditEvent& e : evs) {
    if (!session->submit(e)) continue;
    ++events_submitted;
    if (e.kind == session::EditEvent::Kind::kBrush) brush_submitted.push_back(Clock::now());
  }
  std::vector<sim::TraceRow> rows;
  if (o.sim_clock) rows = session->step_simulated(sim_run, sim_ticks_per_frame);
  watch_drill(rows, obs);
}

/// The picture follows the applied edits: only the changed bricks are uploaded. A brush
/// submitted this frame is waited for (at most --edit-wait-ms) so that this frame shows it.
/// Returns the brushes applied (or refused) so far, which this frame shows.
long Sculpt::take_edits() {
  std::unique_lock<std::mutex> lock(feed.mu);
  const long want = long(brush_submitted.size());
  if (o.edit_wait_ms > 0 && feed.brushes_done < want)
    feed.applied.wait_for(lock, std::chrono::duration<double, std::milli>(o.edit_wait_ms),
                          [&] { return feed.brushes_done >= want; });
  if (!feed.pending.empty()) {
    const auto t0 = Clock::now();
    caster->update(feed.values, feed.pending);
    ++slice_edits;
    update_ms.push_back(ms_since(t0));
    feed.pending.clear();
  }
  if (!feed.last_error.empty()) {
    status = feed.last_error;
    log << "sculpt   " << status << "\n";
    feed.last_error.clear();
  }
  return feed.brushes_done;
}

/// The ray caster's picture with the probe glyphs, and its timings.
void Sculpt::render_picture(const session::Observed& obs, const Vec3& hand_world, const FrameSize& f,
                            const std::function<void()>& meanwhile) {
  const auto r0 = Clock::now();
  const std::vector<gpu::RaycastPrim> prims =
      overlay ? overlay_prims(obs, hand_world, tool, scene.hri.force_limit_n, unit, input.down[0]) : std::vector<gpu::RaycastPrim>{};
  caster->set_in_place(f.direct());
  caster->set_bgra(f.direct() && window->bgra());
  img = caster->render(view, style, f.rw, f.rh, prims, meanwhile);
  render_ms.push_back(ms_since(r0));
  if (img.march_ms >= 0) {
    march_ms.push_back(img.march_ms);
    shade_ms.push_back(img.shade_ms);
    overlay_ms.push_back(img.overlay_ms);
    if (!img.reused) {
      if (o.bench && frame > 0) full_views.push_back({view, f.rw, f.rh});  // (frame 0 is not timed)
      full_march_ms.push_back(img.march_ms);
      full_shade_ms.push_back(img.shade_ms);
      full_overlay_ms.push_back(img.overlay_ms);
    }
  }
}

/// The picture into the window with the panels, edit-to-pixels of the brushes it shows for
/// the first time, and the screenshots the script asked for this frame.
void Sculpt::show(const FrameSize& f, const std::vector<std::string>& shots, long drawn_brushes) {
  const auto p0 = Clock::now();
  const std::vector<std::uint32_t>& shown_px = host_picture(f, !shots.empty());
  // The frame budget learns what a picture drawn whole costs with its upscale to the window,
  // and which part of it does not scale with the picture's pixels.
  if (!img.reused) {
    const double ms = render_ms.back() + (f.direct() ? 0.0 : ms_since(p0));
    budget.measured_whole(double(f.rw) / double(f.fb[0]), ms, ms - scaling_ms(img, render_ms.back()));
  }
  build_panels();
  // A CPU device's picture lies in host memory: the shared-memory path composes the window
  // from it on the host (no device copy; the panels drawn only when they change).
  const std::uint32_t* host_px = f.direct() && window->host_composes() ? caster->mapped_image() : nullptr;
  const bool shown = host_px    ? window->present(host_px, f.fb[0], f.fb[1], window->bgra())
                     : f.direct() ? window->present(caster->image_buffer(), f.fb[0], f.fb[1])
                                  : window->present(shown_px, f.fb[0], f.fb[1]);
  present_ms.push_back(ms_since(p0));
  if (!img.reused) {
    full_render_ms.push_back(render_ms.back());
    full_present_ms.push_back(present_ms.back());
  }
  if (shown || o.sim_clock) measure_latency(drawn_brushes);  // simulated: drawn counts as shown (a recreated swapchain's timing is the X server's)
  write_shots(shots, f.fb, shown_px);
}

/// The picture on the host when it is needed there: read back for a screenshot at the
/// window's size, or scaled up (bilinear) from a lower render scale.
const std::vector<std::uint32_t>& Sculpt::host_picture(const FrameSize& f, bool shot) {
  if (f.direct()) {
    if (shot) img.rgba = caster->last_rgba();
    return img.rgba;
  }
  const auto& fb = f.fb;
  const int rw = f.rw, rh = f.rh;
  upscaled.resize(std::size_t(fb[0]) * std::size_t(fb[1]));
  engine::upscale_bilinear(img.rgba.data(), rw, rh, upscaled.data(), fb[0], fb[1]);
  return upscaled;
}

/// This frame's Dear ImGui panels (drawn by the window's next present). Their figures change
/// every 15 frames (refresh_panel), so that the panels are built again only then, or when
/// the user touches them or a message or load changes.
void Sculpt::build_panels() {
#if ISOTOUCH_WITH_IMGUI
  if (!panels) return;
  if (panel.status != status) panel.status = status;
  if (loading) {
    if (panel.loading != loading->path) panel.loading = loading->path;
    panel.loading_s = ms_since(loading->since) / 1e3;
  } else {
    panel.loading.clear();
    panel.loading_s = 0;
  }
  panels->build(tool, iso_ctl, slices.control(), panel, overlay);
#endif
}

/// The panels' frame time (the mean since the last refresh), force and device status.
void Sculpt::refresh_panel(const session::Observed& obs, std::size_t frames) {
  const std::size_t n = std::min(frames, frame_ms.size());
  double sum = 0;
  for (std::size_t i = frame_ms.size() - n; i < frame_ms.size(); ++i) sum += frame_ms[i];
  panel.frame_ms = n > 0 ? sum / double(n) : 0;
  if (o.sim_clock) panel.frame_ms = o.sim_frame_ms;  // the simulated frame: the same panels every run
  panel.force_n = norm(obs.force_n);
  panel.contact = obs.contact;
  panel.device = mouse ? std::string("mouse (simulated, coupled to the hand)")
                       : haptic.description + ": " + servo::to_string(session->servo_thread()->device_status());
}

/// Edit-to-pixels: from each brush's submission to the first frame that shows it.
void Sculpt::measure_latency(long drawn_brushes) {
  std::lock_guard<std::mutex> lock(feed.mu);
  for (; brushes_measured < drawn_brushes; ++brushes_measured)
    if (feed.brush_changed[std::size_t(brushes_measured)])
      latency_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - brush_submitted[std::size_t(brushes_measured)]).count());
}

void Sculpt::write_shots(const std::vector<std::string>& shots, const std::array<int, 2>& fb, const std::vector<std::uint32_t>& px) {
  std::vector<std::uint32_t> with_slices;
  if (!shots.empty() && slices_shown()) {
    with_slices = px;
    compose_slices(with_slices, fb[0], fb[1]);
  }
  for (const std::string& s : shots) {
    try {
      run::write_png(s, fb[0], fb[1], with_slices.empty() ? px : with_slices);
      if (!o.slices_png.empty()) dump_slices((fs::path(o.slices_png) / fs::path(s).stem()).string());
      log << "sculpt   screenshot " << s << "\n";
    } catch (const std::exception& e) {
      log << "isotouch-sculpt: " << e.what() << "\n";
      code = 1;
    }
  }
}

/// The frame's time; every 15 frames the servo's panel figures and the window's title.
void Sculpt::end_frame(const session::Observed& obs, const std::array<int, 2>& fb) {
  last_fb = fb;
  const auto end = Clock::now();
  if (frame > 0) {
    frame_ms.push_back(std::chrono::duration<double, std::milli>(end - last_frame).count());
    (band_frame ? frame_band_ms : img.reused ? frame_reused_ms : frame_full_ms).push_back(frame_ms.back());
  }
  // A band's render (per row) and its frame, all of it (the rest: a part of every band's
  // frame), size the next band (no time for a first frame: still advanced).
  if (band_frame) still.frame_drawn(band_ms, frame > 0 ? frame_ms.back() : std::numeric_limits<double>::quiet_NaN());
  last_frame = end;
  ++frame;
  if (frame == 2) refresh_panel(obs, 1);  // the first frame time, until the first refresh
  if (frame % 15 == 0) {
    refresh_panel(obs, 15);
    refresh_title(obs, end);
  }
}

void Sculpt::refresh_title(const session::Observed& obs, Clock::time_point now) {
  const session::LiveStats st = session->stats(kPanelLatencies);
  refresh_servo(panel, st, std::chrono::duration<double>(now - panel_refreshed).count());
  panel_refreshed = now;
  std::ostringstream title;
  title << "isotouch-sculpt: " << scene.name << " | " << tool_line(tool) << " | |F| " << fixed(norm(obs.force_n), 2)
        << " N" << (obs.contact ? " contact" : "") << " | frame " << fixed(frame_ms.empty() ? 0 : frame_ms.back())
        << " ms | servo " << st.ticks << " ticks, " << st.missed_deadlines << " missed"
        << (mouse ? std::string() : std::string(" | device ") + servo::to_string(session->servo_thread()->device_status()))
        << (loading ? " | loading " + loading->path : std::string()) << (status.empty() ? "" : " | " + status);
  glfwSetWindowTitle(window->handle(), title.str().c_str());
}

// --- save, export, dropped files, the isovalue ---------------------------------------------

/// The volume as the picture shows it (the applied edits).
engine::Volume Sculpt::edited_volume() {
  engine::Volume out = vol;
  std::lock_guard<std::mutex> lock(feed.mu);
  out.voxels = feed.values;
  return out;
}

void Sculpt::save(const std::string& path) {
  const engine::Volume out = edited_volume();
  try {
    io::save_any_volume(out, path, io::SaveVdbOptions{});  // the format the name asks for
    status = "saved " + path;
  } catch (const std::exception& e) {
    status = std::string("save failed: ") + e.what();
    if (code == 0) code = exit_code::kSaveFailed;  // the session goes on; its exit says so
  }
  log << "sculpt   " << status << "\n";
}

void Sculpt::export_mesh(const std::string& path) {
  const engine::Volume out = edited_volume();
  try {
    const io::Mesh mesh = io::extract_mesh(out, live.iso);
    io::write_mesh(mesh, path, o.mesh_units);  // the format the name asks for
    status = "exported " + path + " (LPS, " + io::to_string(o.mesh_units) + ")";
  } catch (const std::exception& e) {
    status = std::string("export failed: ") + e.what();
    if (code == 0) code = exit_code::kSaveFailed;
  }
  log << "sculpt   " << status << "\n";
}

/// Starts loading a dropped file (a scene, or a volume at this session's isovalue and inside).
void Sculpt::start_load(const std::string& path) {
  Options next = o;
  next.input = path;
  next.script.clear();
  next.record.clear();
  next.carried = nullptr;
  next.iso.reset();
  log << "sculpt   loading " << path << "\n";
  loading = Loading{path, next, BackgroundLoad([next] {
                      auto c = std::make_shared<Carried>();
                      double tau = 0;
                      if (is_scene_path(next.input)) {
                        const io::Scene sc = input_scene(next);
                        c->volume = run::load_scene_volume(sc);
                        tau = sc.hri.tau;
                      } else {
                        ScanInput s = open_scan(next.input);
                        c->volume = std::move(s.volume);
                        c->choice = s.choice;
                        tau = s.choice.iso.tau;
                      }
                      const engine::Volume& v = c->volume;
                      if (!(tau > v.min_value && tau < v.max_value))
                        throw std::runtime_error("isovalue " + fixed(tau, 3) + " is outside its range [" +
                                                 fixed(v.min_value, 3) + ", " + fixed(v.max_value, 3) + "]");
                      return c;
                    }),
                    Clock::now(), frame};
}

/// True when a dropped file has loaded and this session should end for it.
bool Sculpt::poll_load() {
  if (!loading && !drop_queue.empty()) {
    start_load(drop_queue.front());
    drop_queue.pop_front();
  }
  // The simulated clock waits for it (the same frame every run), for a minute at most: a
  // reader blocked longer goes on in the background, as on the real clock.
  if (loading && o.sim_clock && !loading->sim_waited) {
    loading->sim_waited = true;
    if (!loading->result.wait_for(60))
      log << "sculpt   " << loading->path << " still loading after 60 s: the simulated clock goes on without it\n";
  }
  if (!loading || !loading->result.ready()) return false;
  Loading done = std::move(*loading);
  loading.reset();
  try {
    done.next.carried = done.result.get();
    if (const auto& c = done.next.carried->choice) {
      done.next.iso = c->iso.tau;
      done.next.inside = core::to_string(c->iso.inside);
    }
  } catch (const std::exception& e) {
    status = "cannot open " + done.path + ": " + e.what() + " (keeping " + scene.name + ")";
    log << "sculpt   " << status << "\n";
    return false;
  }
  if (!reopen) return false;
  *reopen = done.next;
  log << "sculpt   opening " << done.path << " (loaded in " << fixed(ms_since(done.since) / 1e3, 2) << " s, "
      << frame - done.frame << " frames drawn meanwhile)\n";
  drop_queue.clear();
  return true;
}

/// The isovalue slider let go at `tau`: this session ends and the next one starts at tau
/// with the volume as edited, the camera, the tool and the rest of the script.
bool Sculpt::restart_at(double tau) {
  iso_ctl.committed = false;
  if (!(tau > vol.min_value && tau < vol.max_value) || tau == scene.hri.tau) {
    iso_ctl.value = scene.hri.tau;
    if (tau != scene.hri.tau) {
      status = "isovalue " + fixed(tau, 1) + " is outside the volume's range (" + fixed(vol.min_value, 1) + ", " +
               fixed(vol.max_value, 1) + "): kept " + fixed(scene.hri.tau, 1);
      log << "sculpt   " << status << "\n";
    }
    return false;
  }
  if (!reopen) return false;
  Options next = o;
  next.iso = tau;
  next.record.clear();
  auto carried = carry_over(tau);
  // The rule line the next session prints and shows: how this value was set; the presets stay.
  engine::IsoChoice how{core::Isosurface{tau, scene.hri.inside}, iso_ctl.how.empty() ? "hand" : iso_ctl.how, false, {}};
  if (chosen) {
    how.hounsfield = chosen->hounsfield;
    how.presets = chosen->presets;
  }
  carried->choice = how;
  next.carried = carried;
  *reopen = next;
  log << "sculpt   isovalue " << tau << ": the session restarts with the edited volume (undo history starts afresh"
      << (o.record.empty() ? "" : ", the recording ends here") << ")\n";
  return true;
}

/// A volume given without --iso: loaded once, opened at the isovalue its file and histogram choose.
void Sculpt::open_at_chosen_isovalue() {
  ScanInput s = open_scan(o.input);
  Options at = o;
  at.iso = s.choice.iso.tau;
  at.inside = core::to_string(s.choice.iso.inside);
  scene = input_scene(at);
  vol = std::move(s.volume);
  say_isovalue(s.choice);
}

/// The camera's up and front in patient axes (the volume's physical frame): printed.
void Sculpt::say_camera() {
  log << "sculpt   camera up: " << run::patient_axis(camera.cam.up_phys)
      << ", front: " << run::patient_axis(camera.cam.front_phys) << " (orientation " << vol.orientation() << ")\n";
}

/// The roll control (, and .): the picture turns a quarter about the camera's front axis.
void Sculpt::roll(int quarter_turns) {
  run::roll_camera(camera.cam, quarter_turns);
  say_camera();
}

/// The chosen isovalue and its rule: printed, and shown in the stats panel.
void Sculpt::say_isovalue(const engine::IsoChoice& c) {
  chosen = c;
  panel.isovalue = engine::iso_line(c);
  log << "sculpt   " << panel.isovalue << "\n";
}

/// What the restarted session keeps: the volume as the session holds it once every edit
/// asked for is applied (an open stroke is closed, and the queue drained: simulated, applied
/// now; live, waited for), the camera, the tool and the rest of the script.
std::shared_ptr<Carried> Sculpt::carry_over(double tau) {
  std::vector<session::EditEvent> end;
  stroke.frame(false, false, tool, Vec3{}, 0, 0, end);
  for (const session::EditEvent& e : end)
    if (session->submit(e)) ++events_submitted;
  if (o.sim_clock) session->finish_simulated();
  auto c = std::make_shared<Carried>();
  c->volume = vol;
  {
    std::unique_lock<std::mutex> lock(feed.mu);
    if (!feed.applied.wait_for(lock, std::chrono::seconds(30), [&] { return feed.events_done >= events_submitted; }))
      log << "sculpt   isovalue " << tau << ": " << events_submitted - feed.events_done
          << " edits were still not applied after 30 s: the new session starts without them\n";
    c->volume.voxels = feed.values;
  }
  refresh_range(c->volume);
  c->camera = camera.cam;
  c->tool = tool;
  c->script.assign(script.begin() + long(std::min(next_event, script.size())), script.end());
  return c;
}

// --- the end: the report -------------------------------------------------------------------

/// After the loop: the session stopped, the last screenshot, the figures. Returns the exit code.
int Sculpt::finish() {
  settle_loads();
  const double seconds = std::chrono::duration<double>(Clock::now() - t_start).count();
  close_stroke();
  const session::LiveStats sculpted = session->stats();
  const ServoAlone alone = servo_alone(sculpted);
  stop_session();
  const session::LiveStats st = session->stats();
  write_last_screenshot();
  if (next_event < script.size() && !restarting) log << "script   ended before its event " << next_event << " (--frames or the window closed)\n";
  if (o.stats || o.bench) print_stats(seconds, st);
  drill.report(log, edited_volume(), live.iso, scene.hri.force_limit_n);
  if (o.stats || o.bench) log << "stats    felt tool: " << felt->changes() << " radius changes applied on the servo thread\n";
  if (!mouse) print_device();
  if (o.bench) print_verdicts(sculpted, alone);
  if (o.bench) print_moving_frames();
  // A device that was lost, faulty or refused during the session: as `run --live` (a
  // simulated clock has no servo thread and no device to lose).
  if (const servo::ServoThread* servo = session->servo_thread(); servo != nullptr && code == 0) {
    const servo::DeviceCounters dc = servo->device_counters();
    if (dc.disconnected > 0 || dc.fault > 0 || dc.refused > 0) code = exit_code::kDeviceLost;
  }
  if (!o.record.empty() && code == 0) log << "recorded " << o.record << " (replay: isotouch replay " << o.record << ")\n";
  close_journal();
  if (vk->validation_messages() > 0) {
    log << "isotouch-sculpt: " << vk->validation_messages() << " Vulkan validation messages\n";
    if (code == 0) code = exit_code::kCheckFailed;
  }
  return code;
}

/// --frames reached while a dropped file loads: it opens next, as if it had loaded in time.
/// The window closed (or the script quit, or the isovalue changed) while a file loads: the
/// load is abandoned, not waited for.
void Sculpt::settle_loads() {
  if (o.frames > 0 && frame >= o.frames && !restarting)
    while (loading || !drop_queue.empty()) {
      if (loading) loading->result.wait();
      if (poll_load()) break;
    }
  if (loading)
    log << "sculpt   abandoned loading " << loading->path << " (still reading after "
        << fixed(ms_since(loading->since) / 1e3, 2) << " s)\n";
}

void Sculpt::close_stroke() {
  if (!stroke.open()) return;
  session::EditEvent e;
  e.kind = session::EditEvent::Kind::kEndStroke;
  session->submit(e);
}

/// --bench: the servo alone right after the sculpt, until it has ticked --bench-ticks times
/// (or twice the time that takes at the scene's rate and 5 s more: a stalled servo), so that
/// its misses while sculpting compare with this machine's own, measured in the same run. The
/// window is not redrawn meanwhile.
ServoAlone Sculpt::servo_alone(const session::LiveStats& sculpted) {
  ServoAlone alone;
  if (!o.bench || o.sim_clock || o.bench_ticks <= 0) return alone;
  const auto t0 = Clock::now();
  const double limit_s = 2.0 * double(o.bench_ticks) / scene.hri.rate_hz + 5.0;
  session::LiveStats now = session->stats();
  while (now.ticks - sculpted.ticks < o.bench_ticks &&
         std::chrono::duration<double>(Clock::now() - t0).count() < limit_s) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    now = session->stats();
  }
  alone.ticks = now.ticks - sculpted.ticks;
  alone.missed = now.missed_deadlines - sculpted.missed_deadlines;
  return alone;
}

void Sculpt::stop_session() {
  try {
    if (o.sim_clock) session->finish_simulated();  // what was submitted after the last tick
    // Abandoned in the renderer: the process ends there (no screenshot, no stats, no
    // destructors: the renderer, its field and the device outlive the stuck thread).
    session::stop_or_end_process(*session, "isotouch-sculpt");
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << "\n";
    code = 1;
  }
}

/// A clean end (exit 0, no signal) deletes the journal; any other keeps it for the next start.
void Sculpt::close_journal() {
  if (!journal.journal) return;
  if (code != 0 || session::stop_signal() != 0) {
    log << "journal  kept: " << journal.journal->path() << " (" << journal.journal->edits() << " edits)\n";
    return;
  }
  try {
    journal.journal->close();
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << "\n";
    code = 1;
  }
}

/// --window-shot: what the X server shows in the window now, after the last present.
void Sculpt::write_window_shot() {
  if (o.window_shot.empty()) return;
  try {
    const std::array<int, 2> fb = window->framebuffer_size();
    const std::vector<std::uint32_t> px = window->read_window();
    if (px.empty()) throw std::runtime_error(o.window_shot + ": the window's pixels cannot be read from the X server");
    run::write_png(o.window_shot, fb[0], fb[1], px);
    log << "sculpt   window shot " << o.window_shot << "\n";
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << "\n";
    code = 1;
  }
}

/// --screenshot: the last frame drawn (and --window-shot, --slices-png).
void Sculpt::write_last_screenshot() {
  if (!o.slices_png.empty()) {
    try {
      dump_slices(o.slices_png);
    } catch (const std::exception& e) {
      log << "isotouch-sculpt: " << e.what() << "\n";
      code = 1;
    }
  }
  write_window_shot();
  if (o.screenshot.empty() || img.width <= 0) return;
  try {
    if (img.rgba.empty() && upscaled.empty()) img.rgba = caster->last_rgba();  // drawn straight to the window
    std::vector<std::uint32_t> px = upscaled.empty() ? img.rgba : upscaled;
    const int w = upscaled.empty() ? img.width : last_fb[0], h = upscaled.empty() ? img.height : last_fb[1];
    if (slices_shown()) compose_slices(px, w, h);
    run::write_png(o.screenshot, w, h, px);
    log << "sculpt   screenshot " << o.screenshot << "\n";
  } catch (const std::exception& e) {
    log << "isotouch-sculpt: " << e.what() << "\n";
    code = 1;
  }
}

/// "stats    WHAT: n N, median M ms, p95 P ms, max X ms" (or none).
void stats_line(std::ostream& log, const char* what, const std::vector<double>& v) {
  if (v.empty()) {
    log << "stats    " << what << ": none\n";
    return;
  }
  log << "stats    " << what << ": n " << v.size() << ", median " << fixed(eval::median(v), 2) << " ms, p95 "
      << fixed(eval::percentile(v, 0.95), 2) << " ms, max " << fixed(*std::max_element(v.begin(), v.end()), 2) << " ms\n";
}

void Sculpt::print_stats(double seconds, const session::LiveStats& st) {
  log << "stats    " << frame << " frames in " << fixed(seconds, 2) << " s, window " << last_fb[0] << "x" << last_fb[1]
      << ", rendered at " << img.width << "x" << img.height << " on " << vk->info().name << ", tile starts "
      << (style.tile_starts ? "on" : "off") << "\n";
  stats_line(log, "frame time", frame_ms);
  stats_line(log, "  frames drawn whole (first, camera or style changed)", frame_full_ms);
  stats_line(log, "    render (ray caster, submit to fence and read back; the slice views meanwhile)", full_render_ms);
  stats_line(log, "    march pass (GPU timestamps)", full_march_ms);  // with the shading of its hits
  stats_line(log, "    shade pass (GPU timestamps)", full_shade_ms);  // rays the march's loop budget stopped
  stats_line(log, "    overlay pass (GPU timestamps)", full_overlay_ms);
  stats_line(log, "    present (and the panels)", full_present_ms);
  stats_line(log, "  frames reusing the last picture (only the probe and the edits drawn again)", frame_reused_ms);
  stats_line(log, "  frames refining a still view (a band of rows each)", frame_band_ms);
  log << "stats    still views refined over frames: " << refinements << " started, " << refinements_done
      << " finished, " << refined_reused << " followed by a frame reusing the bands' picture\n";
  stats_line(log, "  the view stopping to its full-resolution picture (its bands and the frame after them)", refined_ms);
  stats_line(log, "render (ray caster; the slice views meanwhile)", render_ms);
  stats_line(log, "  march pass (GPU timestamps)", march_ms);
  stats_line(log, "  shade pass (GPU timestamps)", shade_ms);
  stats_line(log, "  overlay pass (GPU timestamps)", overlay_ms);
  stats_line(log, "present", present_ms);
  stats_line(log, "picture update (changed bricks)", update_ms);
  stats_line(log, "slice views computed again (the HIP or proxy changed voxel, an edit, the window/level)", slice_ms);
  stats_line(log, "edit-to-pixels (submit to the first frame showing it)", latency_ms);
  stats_line(log, "edit-to-haptics", st.edit_to_haptics_ms);
  log << "stats    memory: " << engine::memory_report() << "; the volume " << volume_line(vol) << ", "
      << vol.voxels.size() * sizeof(float) / (1024 * 1024) << " MiB of floats\n";
  print_servo(st);
#if ISOTOUCH_WITH_IMGUI
  if (panels) {
    log << "stats    overlay " << Overlay::version() << " drawn in " << panels->frames_drawn() << " of " << frame
        << " frames, built anew in " << panels->frames_built();
    if (panels->layers_drawn() > 0) log << ", their layer drawn anew in " << panels->layers_drawn();
    log << "\n";
  }
#endif
}

void Sculpt::print_servo(const session::LiveStats& st) {
  log << "stats    servo " << st.ticks << " ticks, " << st.missed_deadlines << " missed deadlines, period error p99 "
      << (st.period_error_p99_us < 0 ? std::string("n/a")
          : st.period_error_p99_beyond ? "> " + fixed(st.period_error_p99_us, 0) + " us (past the histogram)"
                                       : fixed(st.period_error_p99_us, 0) + " us") << ", " << st.faults
      << " faults; edits " << st.edits_requested << " requested, " << st.edits_applied << " applied, "
      << st.edits_refused << " refused, " << st.edits_dropped << " dropped; swapchain recreated "
      << window->recreations() << " times\n";
  if (st.passivity) log << "stats    passivity " << servo::describe(*st.passivity) << "\n";
}

/// A --haptic device's counters and its link's.
void Sculpt::print_device() {
  const servo::DeviceCounters c = session->servo_thread()->device_counters();
  log << "device   " << haptic.description << ": stale " << c.stale << ", disconnected " << c.disconnected << ", fault "
      << c.fault << ", refused " << c.refused << " ticks; " << c.ramps << " ramp-ins, " << c.clamped << " clamped\n";
  if (c.uncalibrated > 0)
    log << "device   waiting for calibration " << c.uncalibrated << " ticks (zero force; not a fault)\n";
  if (haptic.report) {
    const servo::LinkCounters l = haptic.report->counters();
    log << "link     " << l.reports << " reports, " << l.garbage << " refused, " << l.gaps << " missing (gaps), "
        << l.disconnects << " disconnects, " << l.reconnects << " reconnects, " << l.writes << " output reports\n";
  }
}

/// "verdict: WHAT X ms (needs <= L ms[, WHY]): PASS" (or FAIL with the ratio; no samples: FAIL).
void verdict_line(std::ostream& log, const std::string& what, const std::vector<double>& v, double q, double limit,
                  const std::string& why = "") {
  if (v.empty()) {
    log << "verdict: " << what << ": no samples: FAIL\n";
    return;
  }
  const double x = q == 0.5 ? eval::median(v) : eval::percentile(v, q);
  log << "verdict: " << what << " " << fixed(x, 1) << " ms (needs <= " << fixed(limit, 1) << " ms" << why << "): "
      << (x <= limit ? "PASS" : "FAIL (" + fixed(x / limit, 2) + "x the target)") << "\n";
}

}  // namespace

bool servo_misses_pass(long sculpt_missed, long sculpt_ticks, long alone_missed, long alone_ticks, double& allowed) {
  const double ref = alone_ticks > 0 ? double(alone_missed) * double(sculpt_ticks) / double(alone_ticks) : 0.0;
  allowed = ref + 3.0 * std::sqrt(ref);
  return double(sculpt_missed) <= allowed;
}

namespace {

/// Beside the frames-drawn-whole verdicts, their floor: the texel fetches per pixel the march
/// and shade passes made, counted by drawing again (counting pipelines) up to 36 of the
/// frames drawn whole, spread over them, at their cameras and sizes (the volume as it is now,
/// after the edits), per invocation and as whole vectors (a SIMD device's fetch costs every
/// lane of its vector); then, for each count, the time of a pass doing only that many fetches
/// and one store per pixel at the last one's size from a buffer as large as the volume's
/// texels (engine::raycast_floor), submit to fence as
/// the frame times (lavapipe's timestamps around a lone dispatch read near 0 in this process).
void Sculpt::print_floor() {
  if (full_views.empty()) {
    log << "verdict: frames drawn whole: floor: no frames drawn whole\n";
    return;
  }
  const std::size_t n = std::min<std::size_t>(36, full_views.size());
  double march = 0, shade = 0, lanes = 0, pixels = 0;
  caster->set_count_fetches(true);
  for (std::size_t i = 0; i < n; ++i) {
    const WholeFrame& w = full_views[i * full_views.size() / n];
    caster->render(w.view, style, w.width, w.height);
    const engine::RayCaster::FetchCount c = caster->last_fetches();
    march += double(c.march);
    shade += double(c.shade);
    lanes += double(c.march_lanes + c.shade_lanes);
    pixels += double(c.pixels);
  }
  caster->set_count_fetches(false);
  const WholeFrame& last = full_views.back();
  constexpr int kFrames = 9;
  const auto& d = caster->field().grid.dims;  // the fetched texels' bytes: the quads (or the voxels)
  const std::uint64_t bytes = caster->quads() ? std::uint64_t(d[0] + 2) * std::uint64_t(d[1] + 2) * std::uint64_t(d[2] + 2) * 16
                                              : caster->field().values.size() * sizeof(float);
  std::uint64_t used = 0;  // the floor pass's buffer [bytes]
  const auto floor_ms = [&](double per_pixel) {
    const engine::RaycastFloor fl = engine::raycast_floor(*vk, last.width, last.height,
                                                          std::uint32_t(std::lround(per_pixel)), caster->quads(), kFrames, bytes);
    used = fl.bytes;
    return fl.wall_ms;
  };
  const double per_pixel = (march + shade) / pixels, per_lane = lanes / pixels;
  const double ms = floor_ms(per_pixel), lane_ms = floor_ms(per_lane);
  log << "verdict: frames drawn whole: floor: " << fixed(per_pixel, 1) << " fetches per pixel = " << fixed(ms, 2)
      << " ms (march " << fixed(march / pixels, 1) << " + shade " << fixed(shade / pixels, 1)
      << " texel fetches per pixel's invocation; as whole vectors " << fixed(per_lane, 1) << " per pixel = "
      << fixed(lane_ms, 2) << " ms; counted in " << n << " of the "
      << full_views.size() << " frames drawn whole, drawn again; a pass of only that many fetches, rounded ("
      << (caster->quads() ? "4 floats" : "1 float") << " each), and one store per pixel at " << last.width << "x"
      << last.height << " from " << (used >> 20) << " MiB, submit to fence, median of " << kFrames << " frames)\n";
}

/// --bench: the frame time, edit-to-pixels and servo figures against the targets: frames
/// drawn whole (every pixel cast, render scale 1) median <= 33 ms and p95 <= 50 ms; sculpting
/// frames and edit-to-pixels no slower than be320b6's on the chest (35.5 and 39.7 ms median,
/// the quiet machine); the servo's misses while sculpting at most the servo alone's (scaled
/// to the same ticks) + 3 standard deviations of a Poisson count, over >= 20,000 ticks each.
void Sculpt::print_verdicts(const session::LiveStats& sculpted, const ServoAlone& alone) {
  const std::string at = " at " + std::to_string(last_fb[0]) + "x" + std::to_string(last_fb[1]);
  verdict_line(log, "frames drawn whole: frame time median" + at, frame_full_ms, 0.5, 33);
  verdict_line(log, "frames drawn whole: frame time p95", frame_full_ms, 0.95, 50);
  print_floor();
  verdict_line(log, "sculpting frames (reusing the picture): frame time median", frame_reused_ms, 0.5, 35.5,
               ", be320b6's on the chest");
  verdict_line(log, "edit-to-pixels median", latency_ms, 0.5, 39.7, ", be320b6's on the chest");
  if (o.sim_clock || o.bench_ticks <= 0 || alone.ticks <= 0 || sculpted.ticks <= 0) {
    log << "verdict: servo missed deadlines while sculpting " << sculpted.missed_deadlines << " of " << sculpted.ticks
        << " ticks; no servo-alone phase (" << (o.sim_clock ? "simulated clock" : "--bench-ticks 0")
        << "): not measured\n";
    return;
  }
  double allowed = 0;
  const bool fewer = sculpted.ticks < kBenchMinTicks || alone.ticks < kBenchMinTicks;
  const bool pass = servo_misses_pass(sculpted.missed_deadlines, sculpted.ticks, alone.missed, alone.ticks, allowed);
  log << "verdict: servo missed deadlines while sculpting " << sculpted.missed_deadlines << " of " << sculpted.ticks
      << " ticks (" << bench_rounds_run << " rounds) against the servo alone right after " << alone.missed << " of "
      << alone.ticks << " ticks (needs sculpting <= alone scaled to the same ticks + 3 sqrt of it = "
      << fixed(allowed, 1) << ", >= " << kBenchMinTicks << " ticks each): "
      << (fewer ? std::string("FAIL (fewer ticks than that)") : pass ? "PASS" : "FAIL") << "\n";
}

}  // namespace

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
