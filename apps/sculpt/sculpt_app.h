// sculpt_app.h - isotouch-sculpt's session, internal to the app (not installed): the Sculpt
// class (one session of the window, from its input to its report) and the small helpers its
// files share. Its methods are defined by idea, one file each:
//   app.cpp            run_sculpt: the steps in order; the helpers several files use
//   app_setup.cpp      set-up: the input, the probe, the window, the panels, the edits, the
//                      journal, the device, the session, the tools
//   app_felt_tool.cpp  the felt tool: the carve or drill brush felt as a sphere (burr.h)
//   app_frames.cpp     the frame loop: a frame's steps, moving frames and the still view's
//                      refinement, the slice views, the tools, the edits, the picture, the panels
//   app_input.cpp      the script (and the built-in --bench script), GLFW's input callbacks,
//                      the keys, the camera and the hand
//   app_files.cpp      save, export, dropped files, the isovalue
//   app_report.cpp     the end: finish, the stats, the verdicts, the floor
#pragma once
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
#include <cstring>
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
#include "isotouch/materials/label_export.h"
#include "isotouch/materials/label_volume.h"
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

namespace detail {

double ms_since(Clock::time_point t0);
std::string fixed(double v, int p = 1);
/// The scene to sculpt: the scene file, or a scene made for a volume file (app_setup.cpp).
io::Scene input_scene(const Options& o);
/// The stats panel's volume line: dims, spacing, orientation.
std::string volume_line(const engine::Volume& v);
/// The built-in --bench script (app_input.cpp).
std::string bench_script_text();

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

extern Input* g_input;  // GLFW callbacks (one window)
#if ISOTOUCH_WITH_IMGUI
extern Overlay* g_panels;
#endif
// GLFW's input callbacks (app_input.cpp), set by Sculpt::open_window.
void on_cursor(GLFWwindow* w, double x, double y);
void on_button(GLFWwindow* w, int b, int action, int mods);
void on_scroll(GLFWwindow* w, double dx, double dy);
void on_drop(GLFWwindow*, int n, const char** paths);
void on_key(GLFWwindow* w, int key, int scancode, int action, int mods);
void on_char(GLFWwindow* w, unsigned int c);

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
  // A labelled scene's materials (cut_by_material): the slice views' colours, the edited
  // label map saved beside the volume (save).
  std::optional<materials::LabelVolume> labels;
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

}  // namespace detail

}  // namespace isotouch::sculpt
