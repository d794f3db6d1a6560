// live_py.cpp - isotouch.LiveSession: a scene's live session (session::LiveSession) on the
// simulated, null, playback, emulated or USB device, driven from Python.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <sstream>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <thread>

#include "isotouch/io/files.h"
#include "isotouch/io/scene.h"
#include "isotouch/io/scene_servo.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/python/common.h"
#include "isotouch/python/params_arg.h"
#include "isotouch/python/stuck_renderer.h"
#include "isotouch/run/haptic_device.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/run/volume_scene.h"
#include "isotouch/servo/hri.h"
#include "isotouch/session/live_session.h"
#include "isotouch/session/session.h"
#include "isotouch/sim/stability.h"

#include <pybind11/stl.h>

namespace isotouch::python {
namespace {

session::BrushKind brush_kind(const std::string& name) {
  for (const auto k : {session::BrushKind::kAdd, session::BrushKind::kCarve, session::BrushKind::kSmooth,
                       session::BrushKind::kDrill})
    if (name == session::to_string(k)) return k;
  throw py::value_error("kind: '" + name + "', must be 'add', 'carve', 'smooth' or 'drill'");
}

/// The checks a scene file's servo section gets (io/scene.cpp), for a renderer given as
/// HriParams: the ranges of the stiffness, damping and force limit, and the passivity bound
/// K <= 2 (b - |B|) / T for the scene's device and hand damping b at the servo's rate.
/// @throws ValueError naming the field and its value.
void check_servo(const io::Scene& s) {
  const servo::HriParams& p = s.hri;
  const auto bad = [](const std::string& field, double v, const std::string& want) {
    std::ostringstream e;
    e << field << ": " << v << ", must be " << want;
    throw py::value_error(e.str());
  };
  if (!(p.stiffness_n_per_m > 0 && p.stiffness_n_per_m <= 1e6)) bad("stiffness_n_per_m", p.stiffness_n_per_m, "in (0, 1e6] N/m");
  if (!(p.force_limit_n > 0 && p.force_limit_n <= 1000)) bad("force_limit_n", p.force_limit_n, "in (0, 1000] N");
  if (!std::isfinite(p.damping_n_s_per_m)) bad("damping_n_s_per_m", p.damping_n_s_per_m, "finite [N s/m]");
  const double b = s.device.damping_n_s_per_m + s.device.hand_damping_n_s_per_m;
  const double bound = sim::colgate_k_max(b, p.damping_n_s_per_m, 1.0 / s.hri.rate_hz);
  if (p.stiffness_n_per_m > bound) {
    std::ostringstream want;
    want << "at most the stability bound K_max = 2 (b - |B|) / T = " << bound << " N/m (b = device + hand damping "
         << b << " N s/m, B = damping_n_s_per_m " << p.damping_n_s_per_m << ", T = 1 / " << s.hri.rate_hz
         << " Hz): the contact may buzz";
    bad("stiffness_n_per_m", p.stiffness_n_per_m, want.str());
  }
}

/// The isovalue a program gave (tau= or params.tau), said so in the scene's description.
engine::IsoChoice iso_given(const servo::HriParams& hri) {
  engine::IsoChoice choice;
  choice.iso = core::Isosurface{hri.tau, hri.inside};
  choice.rule = "the program (LiveSession's tau)";
  return choice;
}

/// The scene a recorded session on `vol` writes beside its recording: `hri` as its "servo"
/// section (scene_hri: the defaults'), parsed back and compared field by field, so that
/// `isotouch replay` rebuilds the same renderer. @throws std::invalid_argument naming a field
/// of params a scene cannot carry (or would read back otherwise) and its value.
run::VolumeScene recordable_scene(const engine::Volume& vol, const servo::HriParams& hri, bool scene_hri) {
  if (scene_hri) return run::make_volume_scene(vol, iso_given(hri), vol.path);
  run::VolumeScene vs;
  try {
    vs = run::make_volume_scene(vol, iso_given(hri), vol.path, io::servo_section_json(hri));
  } catch (const io::SceneError& e) {  // params the scene's parser refuses (a NaN, a tool on the paper variant)
    throw std::invalid_argument(std::string("record: params cannot be recorded as a scene's servo section: ") + e.what());
  }
  servo::HriParams want = hri;
  want.world_per_device = vs.scene.hri.world_per_device;  // the scene's device section owns it
  want.edit_period_s = vs.scene.hri.edit_period_s;        // every session's is set from its scene's edits
  if (const std::string f = io::unrecordable_field(want, vs.scene.hri); !f.empty())
    throw std::invalid_argument("record: params." + f + " cannot be recorded: the scene written beside the recording "
                                "has no such key or reads it back otherwise, so a replay would render differently; "
                                "leave it at its default to record");
  check_servo(vs.scene);
  return vs;
}

/// The default touch scene `isotouch run VOLUME` makes (run/volume_scene.h) for `vol` at the
/// isovalue and renderer `hri` (`scene_hri`: keep the scene's renderer defaults, only tau and
/// inside from `hri`). Its file name says where it came from; nothing is read from it. With
/// `scene_file` (a recorded session's), the scene's text is written there (atomically) and
/// is its file: what the recording carries and `isotouch replay` reads; `hri` (unless
/// scene_hri) is then its "servo" section, read back equal or refused (recordable_scene).
io::Scene volume_scene(const engine::Volume& vol, const servo::HriParams& hri, bool scene_hri,
                       const std::string& scene_file) {
  if (!scene_file.empty()) {
    const run::VolumeScene vs = recordable_scene(vol, hri, scene_hri);
    io::write_file_atomic(scene_file, vs.json);
    io::Scene s = vs.scene;
    s.file = scene_file;
    return s;  // a recording's renderer is the scene file's
  }
  const run::VolumeScene vs = run::make_volume_scene(vol, iso_given(hri), vol.path);
  io::Scene s = vs.scene;
  if (!scene_hri) {
    const double wpd = s.hri.world_per_device;  // the scene's workspace scale (device section)
    s.hri = hri;
    s.hri.world_per_device = wpd;
    check_servo(s);
  }
  s.file = "isotouch.LiveSession(volume)";
  return s;
}

/// Everything one live session needs, owned together and torn down in order (session first).
class Live {
 public:
  Live(const std::string& scene_path, const std::string& haptic, const std::string& record, const std::string& device,
       bool realtime, double flush_interval_s)
      : scene_(io::load_scene(scene_path)) {
    std::ostringstream log;
    setup_ = run::setup_scene(scene_, run_options(device), log);
    open(haptic, record, realtime, flush_interval_s);
  }
  /// On `volume` at `hri`'s isovalue (scene_hri: the scene defaults' renderer); with `record`,
  /// its scene written to RECORD.scene.json first (the volume must be the file it names).
  Live(engine::Volume volume, const servo::HriParams& hri, bool scene_hri, const std::string& haptic,
       const std::string& record, const std::string& device, bool realtime, double flush_interval_s)
      : scene_(volume_scene(volume, hri, scene_hri, record.empty() ? "" : record + kSceneSuffix)) {
    std::ostringstream log;
    setup_ = run::setup_scene(scene_, std::move(volume), run_options(device), log);
    open(haptic, record, realtime, flush_interval_s);
  }
  /// A recorded volume session's files beside its recording: RECORD + these.
  static constexpr const char* kSceneSuffix = ".scene.json";
  static constexpr const char* kVolumeSuffix = ".nrrd";

 private:
  static run::RunOptions run_options(const std::string& device) {
    run::RunOptions ro;
    ro.device = device;
    ro.progress = false;
    return ro;
  }
  /// The device, the parts (session::Session::open) and the live session, not started.
  void open(const std::string& haptic, const std::string& record, bool realtime, double flush_interval_s) {
    device_ = run::open_haptic_device(haptic, run::device_setup(scene_, setup_), realtime ? 70 : 0);
    session::Opened opened;
    if (setup_.session) {  // the scene's edit session
      opened = session::Session::open(std::move(setup_.session), setup_.hri);
    } else {
      session::SessionOptions so;
      so.field = setup_.live;
      so.hri = setup_.hri;
      so.vk = setup_.vk.get();
      so.history_limit_mib = scene_.edits.history_limit_mib;
      opened = session::Session::open(engine::Volume(setup_.volume), so);
    }
    opened.throw_if_failed();
    parts_ = std::move(opened.session);
    if (const long at = stuck_at_tick_from_env(); at > 0)  // test seam: stop() abandons the servo thread
      stuck_ = std::make_unique<StuckRenderer>(parts_->renderer(), at);
    parts_->attach(*device_.io, config(record, realtime, flush_interval_s), stuck_.get()).throw_if_failed();
    live_ = parts_->live();
  }

 public:
  /// Reached through DeleteLive only, after stop_quietly(), and never for an abandoned servo
  /// thread: the members' destructors free the renderer, the snapshots and the device.
  ~Live() { stop_quietly(); }

  std::string start() { return live_->start(); }
  /// @throws session::ServoAbandoned (isotouch.ServoAbandoned) if the servo thread was left
  ///         inside the renderer: remembered, so this object is then never freed (DeleteLive).
  void stop() {
    if (!live_) return;
    stopped_.store(true);
    try {
      live_->stop();
    } catch (const session::ServoAbandoned&) {
      abandoned_.store(true);
      throw;
    }
  }
  /// stop() for a destructor: an abandoned servo thread is remembered (abandoned()) and
  /// said on stderr, any other error (a recording that could not be completed) dropped: it
  /// cannot be raised from here, and stop() called explicitly raises it.
  void stop_quietly() noexcept {
    try {
      stop();
    } catch (const session::ServoAbandoned& e) {
      std::fprintf(stderr,
                   "isotouch.LiveSession: %s; the session's renderer, snapshots and device are kept (never freed) "
                   "while that thread may still read them\n",
                   e.what());
    } catch (...) {
    }
  }
  /// A stop() left the servo thread stuck in the renderer (session::ServoAbandoned).
  bool abandoned() const { return abandoned_.load(); }
  void pause(bool p) { live_->pause(p); }
  double elapsed_s() const { return live_->elapsed_s(); }
  double duration_s() const { return setup_.script.duration_s; }
  /// The script's length in servo ticks: the simulated hand moves on the servo's ticks, not
  /// on the wall clock.
  long script_ticks() const { return long(std::ceil(setup_.script.duration_s * scene_.hri.rate_hz)); }
  session::LiveSession& session() { return *live_; }
  const run::SceneSetup& setup() const { return setup_; }

  bool brush(const std::string& kind, const py::handle& centre, double radius_m, double strength, double falloff,
             double force_n) {
    session::EditEvent e;
    e.brush.kind = brush_kind(kind);
    e.brush.centre_m = vec3_arg(centre, "centre");
    e.brush.radius_m = radius_m;
    e.brush.strength = strength;
    e.brush.falloff = falloff;
    e.brush.force_n = force_n;
    e.brush.targets = session::default_targets(setup_.volume, setup_.live.iso);
    e.brush.dt_s = 1.0 / scene_.hri.rate_hz;
    if (const std::string why = session::validate(e.brush); !why.empty()) throw py::value_error("brush: " + why);
    refuse_if_stopped("brush");
    return live_->submit(e);
  }
  bool event(session::EditEvent::Kind k, const char* what) {
    refuse_if_stopped(what);
    session::EditEvent e;
    e.kind = k;
    return live_->submit(e);
  }

 private:
  /// An edit after stop() would never be applied: a RuntimeError, never a silent True.
  void refuse_if_stopped(const char* what) const {
    if (stopped_.load())
      throw std::runtime_error(std::string(what) + ": the session is stopped; edits apply only between start() and stop()");
  }
  session::LiveSessionConfig config(const std::string& record, bool realtime, double flush_interval_s) const {
    session::LiveSessionConfig c;
    c.servo.rate_hz = scene_.hri.rate_hz;
    c.servo.force_limit_n = scene_.hri.force_limit_n;  // the gate: min(scene, device)
    c.servo.sched_fifo = c.servo.pin_cpu = c.servo.lock_memory = realtime;
    c.servo.world_T_device = setup_.world_T_device;
    // Period errors kept: the script's length, at least a minute.
    c.servo.record_ticks = std::size_t(std::ceil(std::max(setup_.script.duration_s, 60.0) * scene_.hri.rate_hz)) + 16;
    if (scene_.edits.present && !scene_.edits.button_down.empty()) {
      session::ButtonDrill d;
      d.brush = run::make_brush(run::brush_at_tool(scene_, setup_.volume, scene_.edits.brush),
                                session::default_targets(setup_.volume, setup_.live.iso), {},
                                scene_.edits.every_ticks / scene_.hri.rate_hz, 0.0);
      d.every_ticks = scene_.edits.every_ticks;
      c.drill = d;
    }
    c.flush_interval_s = flush_interval_s;
    c.record_path = record;
    if (!record.empty()) c.record_header = run::recording_header(scene_, setup_);
    return c;
  }

  io::Scene scene_;
  run::SceneSetup setup_;
  run::HapticDevice device_;  // before parts_: outlives the live session that drives it
  /// Null unless the test seam is on (kStuckAtTickEnv); before parts_: outlives the servo thread.
  std::unique_ptr<StuckRenderer> stuck_;
  /// The edit session, its snapshots, the renderer and the live session (session::Session).
  std::unique_ptr<session::Session> parts_;
  session::LiveSession* live_ = nullptr;  // parts_'s
  std::atomic<bool> abandoned_{false};  // set by stop() (GIL released), read by DeleteLive
  std::atomic<bool> stopped_{false};    // stop() was called: edits are refused
};

/// How the Python object frees its Live: stopped first; if that stop (or an earlier one)
/// abandoned the servo thread inside the renderer, the Live is leaked on purpose, whole: the
/// thread may still read the renderer, the snapshots it holds (parts_: the buffer, the edit
/// session's) and the device, and freeing them would be a use after free should the renderer
/// ever return (ServoThread::stop). The C++ callers end the process instead
/// (session::stop_or_end_process); a Python interpreter is not the binding's to end.
struct DeleteLive {
  void operator()(Live* l) const noexcept {
    l->stop_quietly();
    if (l->abandoned()) return;  // leaked: see above
    delete l;
  }
};

py::dict observed(const session::Observed& o) {
  py::dict d;
  d["tick"] = o.tick;
  d["hip"] = py::make_tuple(o.hip_m.x, o.hip_m.y, o.hip_m.z);
  d["vhip"] = py::make_tuple(o.vhip_m.x, o.vhip_m.y, o.vhip_m.z);
  d["force"] = py::make_tuple(o.force_n.x, o.force_n.y, o.force_n.z);
  d["contact"] = o.contact;
  d["version"] = o.version;
  return d;
}

py::dict stats(const session::LiveStats& s) {
  py::dict d;
  d["ticks"] = s.ticks, d["missed_deadlines"] = s.missed_deadlines, d["faults"] = s.faults;
  d["edits_requested"] = s.edits_requested, d["edits_applied"] = s.edits_applied;
  d["edits_refused"] = s.edits_refused, d["edits_dropped"] = s.edits_dropped, d["edits_merged"] = s.edits_merged;
  d["ticks_not_recorded"] = s.ticks_not_recorded, d["publications"] = s.publications;
  d["edit_to_haptics_ms"] = py::array_t<double>(py::ssize_t(s.edit_to_haptics_ms.size()), s.edit_to_haptics_ms.data());
  d["period_error_p99_us"] = s.period_error_p99_us;
  d["setup_note"] = s.setup_note, d["record_error"] = s.record_error;
  return d;
}

/// Sleeps `seconds` with the GIL released, looking for signals every 20 ms: Ctrl-C stops the
/// session (zero force, recording completed) and raises KeyboardInterrupt.
void wait_session(Live& l, double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    {
      py::gil_scoped_release nogil;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    if (PyErr_CheckSignals() != 0) {
      {
        py::gil_scoped_release nogil;
        l.stop();
      }
      throw py::error_already_set();
    }
  }
}

/// Sleeps, GIL released, until the servo has run `ticks` ticks since start (what the simulated
/// hand moves on: a loaded machine runs them later, never fewer), looking for signals every
/// 2 ms as wait_session does. @throws TimeoutError naming the tick reached when `timeout_s`
/// [s] of wall clock pass first (a stalled or never started servo).
void wait_ticks(Live& l, long ticks, double timeout_s) {
  if (!std::isfinite(timeout_s) || timeout_s < 0)
    throw py::value_error("wait_ticks: timeout_s must be a finite number of seconds >= 0, not " + std::to_string(timeout_s));
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (l.session().observe().tick + 1 < ticks) {
    if (std::chrono::steady_clock::now() >= end) {
      const std::string why = "wait_ticks: " + std::to_string(l.session().observe().tick + 1) + " of " +
                              std::to_string(ticks) + " ticks run after timeout_s " + std::to_string(timeout_s) + " s";
      PyErr_SetString(PyExc_TimeoutError, why.c_str());
      throw py::error_already_set();
    }
    {
      py::gil_scoped_release nogil;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    if (PyErr_CheckSignals() != 0) {
      {
        py::gil_scoped_release nogil;
        l.stop();
      }
      throw py::error_already_set();
    }
  }
}

using LivePtr = std::unique_ptr<Live, DeleteLive>;

LivePtr live_on_scene(const std::string& scene, const std::string& haptic, const std::string& record,
                      const std::string& device, bool realtime, double flush_interval_s, std::optional<double> tau) {
  if (tau) throw py::value_error("tau: the scene " + scene + " gives its own isovalue (its 'isovalue'); tau is for a "
                                 "Volume or an array");
  py::gil_scoped_release nogil;
  return LivePtr(new Live(scene, haptic, record, device, realtime, flush_interval_s));
}

/// A live session on `volume` (moved in: the caller's own copy, which the session edits).
LivePtr live_on_own_volume(engine::Volume volume, std::optional<double> tau, const py::object& params,
                           const std::string& haptic, const std::string& record, const std::string& device,
                           bool realtime, double flush_interval_s) {
  const auto hri = params_arg<servo::HriParams>(params, "LiveSession", "HriParams", tau, "tau", "a Volume");
  if (volume.path.empty()) volume.path = kInMemoryVolumeName;  // named in its scene and errors, never a file
  if (!record.empty())  // the files beside the recording are new: a user's own file is never replaced
    for (const char* suffix : {Live::kVolumeSuffix, Live::kSceneSuffix})
      if (std::filesystem::exists(record + suffix))
        throw py::value_error("record: '" + record + "': " + record + suffix +
                              " exists (a session on a volume writes its volume and scene there): give another record path");
  py::gil_scoped_release nogil;
  // params a recording's scene cannot carry: refused before any file is written.
  if (!record.empty() && !params.is_none()) recordable_scene(volume, hri, false);
  if (!record.empty()) {  // the volume as a file beside the recording, read back: replay reads the same bits
    const std::string file = record + Live::kVolumeSuffix;
    io::save_any_volume(volume, file);
    volume = io::load_any_volume(file);
  }
  return LivePtr(new Live(std::move(volume), hri, params.is_none(), haptic, record, device, realtime, flush_interval_s));
}

LivePtr live_on_volume(const engine::Volume& volume, std::optional<double> tau, const py::object& params,
                       const std::string& haptic, const std::string& record, const std::string& device, bool realtime,
                       double flush_interval_s) {
  // The session edits its own copy: the caller's Volume stays as it was.
  return live_on_own_volume(engine::Volume(volume), tau, params, haptic, record, device, realtime, flush_interval_s);
}

LivePtr live_on_array(const py::array& array, const py::handle& spacing, const py::handle& origin,
                      const std::string& axes, std::optional<double> tau, const py::object& params,
                      const std::string& haptic, const std::string& record, const std::string& device, bool realtime,
                      double flush_interval_s) {
  const auto volume = volume_from_numpy(array, spacing, origin, py::none(), axes, "m");
  // The volume was made here for the session alone: moved in, not copied again.
  return live_on_own_volume(std::move(*volume), tau, params, haptic, record, device, realtime, flush_interval_s);
}

}  // namespace

void bind_live(py::module_& m) {
  using K = session::EditEvent::Kind;
  py::class_<Live, LivePtr>(m, "LiveSession", R"(A volume live: the servo thread at the scene's rate on a device,
an edit thread applying brushes, a streaming recorder (session/live_session.h), all built by
the one owning entry point session::Session::open.

LiveSession(scene, haptic='sim', record='', device='cpu', realtime=False, flush_interval_s=0.1):
a scene JSON file (its volume, isovalue, renderer, script).
LiveSession(volume, *, tau, params=None, haptic='sim', device='cpu', ...): an isotouch.Volume
at the isovalue tau [volume value units] (required: a volume carries none; or params.tau).
params an isotouch.HriParams for the renderer (None: the scene defaults, values above tau
inside); the scripted hand of 'sim' is `isotouch run VOLUME`'s default touch.
LiveSession(array, *, spacing, origin=(0, 0, 0), axes='zyx', tau, ...): the same on a float32
numpy array, spacing and origin [m] as isotouch.Volume(array, spacing, origin, axes=axes) takes
them (Volume.from_mm for millimetres).

haptic as `run --live --haptic` (sim, null, playback:FILE, emu:SOCKET, hid:VID:PID); record a
recording file ('' none; on a volume or array, its volume and scene are written beside it as
RECORD.nrrd and RECORD.scene.json, params= as the scene's servo section: ValueError for one no
scene key carries);
device 'cpu' (CPU brushes) or a Vulkan device. Frames: points (centre, hip, vhip) are
grid-world [m] (origin + spacing * index). Use as a context manager: leaving it stops the
session (servo first, its last force an exact zero).)")
      .def(py::init(&live_on_scene), py::arg("scene"), py::arg("haptic") = "sim", py::arg("record") = "",
           py::arg("device") = "cpu", py::arg("realtime") = false, py::arg("flush_interval_s") = 0.1, py::kw_only(),
           py::arg("tau") = py::none())
      .def(py::init(&live_on_volume), py::arg("volume"), py::kw_only(), py::arg("tau") = py::none(),
           py::arg("params") = py::none(), py::arg("haptic") = "sim", py::arg("record") = "", py::arg("device") = "cpu",
           py::arg("realtime") = false, py::arg("flush_interval_s") = 0.1)
      .def(py::init(&live_on_array), py::arg("array"), py::kw_only(), py::arg("spacing"),
           py::arg("origin") = py::make_tuple(0.0, 0.0, 0.0), py::arg("axes") = "zyx", py::arg("tau") = py::none(),
           py::arg("params") = py::none(), py::arg("haptic") = "sim", py::arg("record") = "", py::arg("device") = "cpu",
           py::arg("realtime") = false, py::arg("flush_interval_s") = 0.1)
      .def("start", &Live::start, "start the recorder, edit and servo threads; returns what the system refused")
      .def("stop", &Live::stop, py::call_guard<py::gil_scoped_release>(),
           "stop (idempotent); raises isotouch.ServoAbandoned if the servo thread was left stuck in the renderer "
           "(force off, recording completed; the session is then never freed)")
      .def("pause", &Live::pause, py::arg("paused") = true, "zero force every tick while paused")
      .def("wait", &wait_session, py::arg("seconds"), "sleep, GIL released; Ctrl-C stops the session and raises")
      .def_property_readonly("elapsed_s", &Live::elapsed_s, "[s] since start")
      .def_property_readonly("duration_s", &Live::duration_s, "the scene script's length [s]")
      .def_property_readonly("script_ticks", &Live::script_ticks,
                             "the scene script's length in servo ticks (duration_s x the servo's rate): the "
                             "simulated hand moves on ticks, so wait_ticks(script_ticks) sees the whole script")
      .def("wait_ticks", &wait_ticks, py::arg("ticks"), py::arg("timeout_s") = 120.0,
           "sleep, GIL released, until the servo has run `ticks` ticks since start(); TimeoutError after "
           "timeout_s [s] of wall clock; Ctrl-C stops the session and raises")
      .def_property_readonly("volume", [](const Live& l) { return std::make_shared<engine::Volume>(l.setup().volume); },
                             "a copy of the unedited volume")
      .def("brush", &Live::brush, py::arg("kind"), py::arg("centre"), py::arg("radius_m") = 2e-3,
           py::arg("strength") = 100.0, py::arg("falloff") = 0.5, py::arg("force_n") = 0.0,
           "submit a brush ('add', 'carve', 'smooth', 'drill'), centre grid-world [m]; False if the queue is full; "
           "RuntimeError after stop()")
      .def("begin_stroke", [](Live& l) { return l.event(K::kBeginStroke, "begin_stroke"); })
      .def("end_stroke", [](Live& l) { return l.event(K::kEndStroke, "end_stroke"); })
      .def("undo", [](Live& l) { return l.event(K::kUndo, "undo"); })
      .def("redo", [](Live& l) { return l.event(K::kRedo, "redo"); })
      .def("observe", [](Live& l) { return observed(l.session().observe()); },
           "the latest tick: hip, vhip [m, grid-world], force [N], contact, version")
      .def("stats", [](Live& l) { return stats(l.session().stats()); }, "counters (complete after stop())")
      .def("__enter__", [](Live& l) -> Live& {
        l.start();
        return l;
      }, py::return_value_policy::reference)
      .def("__exit__", [](Live& l, py::args) {
        py::gil_scoped_release nogil;
        l.stop();
      });
}

}  // namespace isotouch::python
