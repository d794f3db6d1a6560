#include "isotouch/run/live_run.h"
#include "isotouch/service/igtl_device.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "isotouch/core/exit_codes.h"
#include "isotouch/io/files.h"
#include "isotouch/run/haptic_device.h"
#include "isotouch/servo/report_device.h"
#include "isotouch/servo/sdk_device.h"
#include "isotouch/servo/hri.h"
#include "isotouch/session/live_session.h"
#include "isotouch/io/record.h"
#include "isotouch/io/run_folder.h"
#include "isotouch/run/run_report.h"
#include "isotouch/sim/sim_device_io.h"
#include "isotouch/eval/stats.h"
#include "isotouch/session/stop_signal.h"
#include "isotouch/run/trace_csv.h"
#include "isotouch/run/trace_figures.h"

namespace isotouch::run {
namespace fs = std::filesystem;
namespace {

std::string ms(double v) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << v;
  return s.str();
}

/// The timeline as events due at a time: single applications, strokes (begin, an
/// application every edits.every_ticks ticks, end), undo and redo.
struct Due {
  double t_s;
  session::EditEvent::Kind kind;
  const io::TimedEdit* entry;  // brushes only
};

std::vector<Due> timeline(const io::Scene& scene) {
  std::vector<Due> due;
  const double every_s = scene.edits.every_ticks / scene.hri.rate_hz;
  using K = session::EditEvent::Kind;
  for (const io::TimedEdit& t : scene.edits.timeline) {
    if (t.kind == "undo" || t.kind == "redo") {
      due.push_back({t.t_s, t.kind == "undo" ? K::kUndo : K::kRedo, nullptr});
    } else if (t.duration_s <= 0) {
      due.push_back({t.t_s, K::kBrush, &t});
    } else {
      due.push_back({t.t_s, K::kBeginStroke, nullptr});
      for (double s = t.t_s; s < t.t_s + t.duration_s; s += every_s) due.push_back({s, K::kBrush, &t});
      due.push_back({t.t_s + t.duration_s, K::kEndStroke, nullptr});
    }
  }
  std::stable_sort(due.begin(), due.end(), [](const Due& a, const Due& b) { return a.t_s < b.t_s; });
  return due;
}

session::LiveSessionConfig live_config(const io::Scene& scene, const SceneSetup& setup, const session::EditSession& edits,
                                       const LiveOptions& o) {
  session::LiveSessionConfig c;
  c.servo.rate_hz = scene.hri.rate_hz;
  c.servo.force_limit_n = scene.hri.force_limit_n;  // the gate: min(scene, device)
  c.servo.passivity_control = scene.passivity_control;
  c.servo.sched_fifo = o.sched_fifo;
  c.servo.pin_cpu = o.sched_fifo;
  c.servo.lock_memory = o.sched_fifo;
  c.servo.world_T_device = setup.world_T_device;
  c.servo.record_ticks = std::size_t(std::ceil(setup.script.duration_s * scene.hri.rate_hz)) + 16;
  const session::BrushTargets targets = session::default_targets(setup.volume, setup.live.iso);
  if (scene.edits.present && !scene.edits.button_down.empty()) {
    session::ButtonDrill d;
    d.brush = make_brush(brush_at_tool(scene, setup.volume, scene.edits.brush), targets, {},
                         scene.edits.every_ticks / scene.hri.rate_hz, 0.0);
    d.every_ticks = scene.edits.every_ticks;
    c.drill = d;
  }
  c.flush_interval_s = o.flush_interval_s;
  c.record_path = o.run.record_path;
  if (!c.record_path.empty()) {
    c.record_header.scene_path = std::filesystem::absolute(scene.file).string();
    std::ifstream in(scene.file, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    c.record_header.scene_text = text.str();
    c.record_header.rate_hz = scene.hri.rate_hz;
    c.record_header.volume_crc32 = io::volume_crc32(edits.volume());
  }
  return c;
}

/// Submits the timeline's events that are due at `t` (index `next` moves on).
void submit_due(const std::vector<Due>& due, std::size_t& next, double t, const io::Scene& scene, const SceneSetup& setup,
                session::LiveSession& live) {
  const session::BrushTargets targets = session::default_targets(setup.volume, setup.live.iso);
  for (; next < due.size() && due[next].t_s <= t; ++next) {
    session::EditEvent e;
    e.kind = due[next].kind;
    if (e.kind == session::EditEvent::Kind::kBrush) {
      const io::TimedEdit& te = *due[next].entry;
      const session::Observed now = live.observe();
      const core::Vec3 c = te.at_vhip ? now.vhip_m : setup.volume.to_grid(te.at_m);
      const double f = te.brush.force_n >= 0 ? te.brush.force_n : core::norm(now.force_n);
      e.brush = make_brush(te.at_vhip ? brush_at_tool(scene, setup.volume, te.brush) : te.brush, targets, c,
                           scene.edits.every_ticks / scene.hri.rate_hz, f);
    }
    live.submit(e);
  }
}

void print_stats(const session::LiveStats& s, double seconds, std::ostream& log) {
  log << "live     " << s.ticks << " ticks in " << ms(seconds) << " s, " << s.missed_deadlines << " missed deadlines, "
      << s.faults << " faults\n";
  log << "edits    " << s.edits_requested << " requested, " << s.edits_applied << " applied, " << s.edits_refused
      << " refused, " << s.edits_dropped << " dropped (queue full or stopped), " << s.publications
      << " snapshots published\n";
  if (!s.edit_to_haptics_ms.empty())
    log << "latency  edit-to-haptics (request tick to the first tick reading the new snapshot), "
        << s.edit_to_haptics_ms.size() << " edits: median " << ms(eval::median(s.edit_to_haptics_ms)) << " ms, p99 "
        << ms(eval::percentile(s.edit_to_haptics_ms, 0.99)) << " ms, max "
        << ms(*std::max_element(s.edit_to_haptics_ms.begin(), s.edit_to_haptics_ms.end())) << " ms\n";
}

/// Forwards to the device and measures what the servo sent (atomics only: servo thread).
class ForceMeter final : public servo::HapticDeviceIO {
 public:
  explicit ForceMeter(servo::HapticDeviceIO& d) : d_(d) {}
  core::Vec3 read_position_m() override { return d_.read_position_m(); }
  std::uint32_t buttons() override { return d_.buttons(); }
  servo::DeviceReading read() override { return d_.read(); }
  servo::DeviceCaps caps() const override { return d_.caps(); }
  const std::atomic<std::uint64_t>* enable_force(bool on, double stall_s) override {
    return d_.enable_force(on, stall_s);
  }
  void answer(std::uint64_t s) override { d_.answer(s); }
  void write_force_n(const core::Vec3& f) override {
    const double m = core::norm(f);
    if (m > 0) forced_.fetch_add(1, std::memory_order_relaxed);
    if (m > max_.load(std::memory_order_relaxed)) max_.store(m, std::memory_order_relaxed);
    d_.write_force_n(f);
  }
  long forced_ticks() const { return forced_.load(); }
  double max_force_n() const { return max_.load(); }

 private:
  servo::HapticDeviceIO& d_;
  std::atomic<long> forced_{0};
  std::atomic<double> max_{0};
};

/// Keeps the renderer's ticks for trace.csv (`--out`): one preallocated row per tick,
/// filled on the servo thread (no allocation, lock or syscall: steady_clock is the vDSO),
/// read after the session stopped. Ticks past the capacity are counted, not kept; ticks the
/// servo held (device not ok, paused) did not reach the renderer and have no row.
class TracingRenderer final : public servo::Renderer {
 public:
  TracingRenderer(servo::Renderer& inner, std::size_t capacity, double rate_hz)
      : inner_(inner), rows_(capacity), period_s_(1.0 / rate_hz) {}
  const char* name() const override { return inner_.name(); }
  void reset() override { inner_.reset(); }
  servo::HriTick tick(const core::FieldView& field, const core::Vec3& hip_m, double dt_s) override {
    const auto t0 = std::chrono::steady_clock::now();
    const servo::HriTick out = inner_.tick(field, hip_m, dt_s);
    const auto t1 = std::chrono::steady_clock::now();
    t_s_ += dt_s > 0 && std::isfinite(dt_s) ? dt_s : period_s_;
    if (kept_ >= rows_.size()) {
      ++lost_;
      return out;
    }
    rows_[kept_++] = sim::trace_row(t_s_, hip_m, out, std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count());
    return out;
  }
  /// After the session stopped: the rows, with the script's hand target at each tick's time.
  std::vector<sim::TraceRow> trace(const sim::TouchScript& script) const {
    std::vector<sim::TraceRow> t(rows_.begin(), rows_.begin() + std::ptrdiff_t(kept_));
    for (sim::TraceRow& r : t) {
      core::Vec3 v;
      script.at(r.t_s, r.hand_target_m, v);
    }
    return t;
  }
  long lost() const { return lost_; }

 private:
  servo::Renderer& inner_;
  std::vector<sim::TraceRow> rows_;
  std::size_t kept_ = 0;
  long lost_ = 0;
  double t_s_ = 0, period_s_;
};

/// `run --live --out DIR`: trace.csv, report.md and summary.json ("complete", with a "live"
/// section; "interrupted" when a signal stopped the session) from the renderer's ticks.
void write_live_outputs(const io::Scene& scene, SceneSetup& setup, const TracingRenderer& tracer,
                        const session::LiveStats& s, double seconds, const std::string& device, io::RunFolder& folder,
                        std::ostream& log) {
  const std::vector<sim::TraceRow> trace = tracer.trace(setup.script);
  RunMetrics& m = setup.metrics;
  const auto [found, raw_found] = trace_figures(trace, setup, nullptr, m);
  const fs::path dir(folder.dir());
  if (scene.write_trace) io::write_file_atomic((dir / "trace.csv").string(), trace_csv(trace, setup.volume));
  if (const int sig = session::stop_signal(); sig != 0) {
    folder.mark_interrupted("live session, after " + ms(seconds) + " s (trace.csv holds its ticks)", sig);
    log << "outputs  " << dir.string() << "/: summary.json says \"status\": \"interrupted\"\n";
    return;
  }
  nlohmann::ordered_json j = summary_json(scene, setup, m, found, raw_found, false);
  j["live"] = {{"seconds", seconds},
               {"device", device},
               {"ticks", s.ticks},
               {"ticks_traced", trace.size()},
               {"ticks_not_traced", tracer.lost()},
               {"missed_deadlines", s.missed_deadlines},
               {"faults", s.faults},
               {"edits_applied", s.edits_applied},
               {"passivity", passivity_json(s.passivity)},
               {"note", "trace.csv holds the renderer's ticks (its force before the servo's ramp-in and clamp); "
                        "ticks the servo held (device not ok) are not in it; the surface error is measured against "
                        "the volume before any edit"}};
  io::write_file_atomic((dir / "report.md").string(),
                        report_markdown(scene, setup, m, found, raw_found, false) +
                            "\n## Live session\n\n" + std::to_string(s.ticks) + " servo ticks in " + ms(seconds) +
                            " s on " + device + ", " + std::to_string(s.missed_deadlines) +
                            " missed deadlines; trace.csv holds the renderer's " + std::to_string(trace.size()) +
                            " ticks.\n");
  io::write_file_atomic((dir / "summary.json").string(), j.dump(2) + "\n");  // last: "complete"
  log << "outputs  " << dir.string() << "/: trace.csv, report.md, summary.json (" << trace.size() << " ticks)\n";
}

/// The device's figures after the run.
void print_device(const HapticDevice& d, const ForceMeter& meter, const servo::ServoThread& servo, std::ostream& log) {
  const servo::DeviceCounters c = servo.device_counters();
  log << "device   " << d.description << ": " << meter.forced_ticks() << " ticks with force, max |F| "
      << ms(meter.max_force_n()) << " N; stale " << c.stale << ", disconnected " << c.disconnected << ", fault "
      << c.fault << ", refused " << c.refused << " ticks; " << c.ramps << " ramp-ins, " << c.clamped << " clamped, "
      << c.late_restarts << " late restarts\n";
  if (c.uncalibrated > 0)
    log << "device   waiting for calibration " << c.uncalibrated << " ticks (zero force; not a fault)\n";
  if (d.report) {
    const servo::LinkCounters l = d.report->counters();
    log << "link     " << l.reports << " reports, " << l.garbage << " refused, " << l.gaps << " missing (gaps), "
        << l.duplicates << " duplicates, " << l.reordered << " reordered, " << l.disconnects << " disconnects, "
        << l.reconnects << " reconnects, " << l.writes << " output reports, " << l.stalls << " stalls\n";
    if (!d.report->last_refusal().empty()) log << "link     last refused: " << d.report->last_refusal() << "\n";
    if (!d.report->last_error().empty() && d.report->last_error() != d.report->last_refusal())
      log << "link     last error: " << d.report->last_error() << "\n";
  }
  if (d.sdk) log << "sdk      " << d.sdk->stalls() << " stalls; " << d.sdk->sdk_status() << "\n";
  if (d.igtl)
    log << "link     " << d.igtl->forces_sent() << " Force TRANSFORMs sent, " << d.igtl->stalls()
        << " stalls (the servo silent for its stall time: the peer got a zero at once, then the servo's ramp)\n";
}

}  // namespace

int write_hand_path(const io::Scene& scene, const std::string& path, std::ostream& log) {
  RunOptions ropt;
  ropt.progress = false;
  const SceneSetup setup = setup_scene(scene, ropt, log);
  std::ostringstream csv;
  csv << "t_s,x_m,y_m,z_m\n" << std::setprecision(9);
  const double step = 1e-3;
  for (long k = 0; double(k) * step <= setup.script.duration_s; ++k) {
    core::Vec3 p, v;
    setup.script.at(double(k) * step, p, v);
    const core::Vec3 d = setup.world_T_device.to_device(p);
    csv << double(k) * step << ',' << d.x << ',' << d.y << ',' << d.z << '\n';
  }
  io::write_file_atomic(path, csv.str());  // whole or not at all
  log << "hand path " << path << ": " << setup.script.duration_s << " s of the scene's scripted hand, device frame "
      << "(isotouch-devemu --path " << path << ")\n";
  return 0;
}

namespace {

int run_live_in(const io::Scene& scene, const LiveOptions& o, io::RunFolder* folder, std::ostream& log) {
  RunOptions ropt = o.run;
  SceneSetup setup = setup_scene(scene, ropt, log);
  // Every live session edits through an EditSession (one without an "edits" section too:
  // the API may edit); its first snapshot is what the servo reads first.
  std::unique_ptr<session::EditSession> own;
  session::EditSession* edits = setup.session.get();
  if (!edits) {
    own = std::make_unique<session::EditSession>(setup.volume, setup.vk.get(), setup.live, scene.edits.history_limit_mib);
    edits = own.get();
  }
  servo::TripleBuffer<core::SampleField> buffer;
  buffer.publish(edits->current());
  servo::HriRenderer hri(setup.hri);
  const std::size_t trace_rows = std::size_t(std::ceil(setup.script.duration_s * scene.hri.rate_hz)) + 16;
  TracingRenderer tracer(hri, folder ? trace_rows : 0, scene.hri.rate_hz);
  servo::Renderer& renderer = folder ? static_cast<servo::Renderer&>(tracer) : hri;
  HapticDevice device = open_haptic_device(o.haptic, device_setup(scene, setup), o.sched_fifo ? 70 : 0);
  ForceMeter meter(*device.io);
  session::install_stop_handlers();
  session::LiveSession live(*edits, buffer, renderer, meter, live_config(scene, setup, *edits, o));
  const std::vector<Due> due = timeline(scene);
  std::size_t next = 0;
  const double duration = setup.script.duration_s;
  log << "live     " << scene.name << ": " << ms(duration) << " s at " << scene.hri.rate_hz << " Hz"
      << (o.run.record_path.empty() ? std::string() : ", recording to " + o.run.record_path) << "\n";
  if (device.kind != "sim") log << "device   " << device.description << "\n";
  if (device.kind == "sim" && setup.script.lift_retrace)
    log << "script   lift_retrace is for simulated runs: this live run's hand lifts straight along the contact normal\n";
  if (device.report && !device.report->realtime_note().empty()) log << "device   " << device.report->realtime_note() << "\n";
  if (const std::string note = live.start(); !note.empty()) log << "servo    " << note << "\n";
  int last_second = 0;
  const bool tty = o.run.progress && ::isatty(STDERR_FILENO);
  bool waiting = false;  // the device was last seen uncalibrated
  while (live.elapsed_s() < duration && session::stop_signal() == 0) {
    submit_due(due, next, live.elapsed_s(), scene, setup, live);
    std::this_thread::sleep_for(std::chrono::microseconds(500));
    // Not calibrated yet: zero force, not a fault (the run goes on; the force ramps in once it is).
    if (const bool now = live.servo_thread()->device_status() == servo::DeviceStatus::kUncalibrated; now != waiting) {
      waiting = now;
      log << "device   " << (now ? "waiting for calibration (zero force until the device is calibrated)"
                                   : "calibrated: the force ramps in")
          << " at " << ms(live.elapsed_s()) << " s\n";
    }
    if (o.run.progress && int(live.elapsed_s()) > last_second) {
      last_second = int(live.elapsed_s());
      const session::LiveStats s = live.stats();
      std::cerr << "live     " << last_second << " s, " << s.ticks << " ticks, " << s.missed_deadlines << " missed, "
                << s.edits_applied << " edits, device " << servo::to_string(live.servo_thread()->device_status())
                << (tty ? "    \r" : "\n") << std::flush;
    }
  }
  if (tty) std::cerr << "\n";
  const double seconds = live.elapsed_s();
  // A servo thread abandoned in the renderer (force off, recording completed) ends the
  // process there, the folder marked failed first: unwinding would free the renderer, the
  // field and the device that thread may still read.
  session::stop_or_end_process(live, "isotouch run --live", [folder](const std::string& what) {
    session::clear_last_words();
    if (folder) folder->mark_failed(what);
  });
  const session::LiveStats s = live.stats();
  if (session::stop_signal() != 0) log << "live     stopped by signal " << session::stop_signal() << " after " << ms(seconds) << " s\n";
  print_stats(s, seconds, log);
  // The device's figures: always for a real or emulated device; for the simulated ones
  // only when the servo refused or zeroed something (a non-finite simulated HIP).
  const servo::DeviceCounters dc = live.servo_thread()->device_counters();
  const bool device_lost = dc.disconnected > 0 || dc.fault > 0 || dc.refused > 0;
  if (device.report || device.sdk || device.igtl || device_lost || dc.stale > 0) print_device(device, meter, *live.servo_thread(), log);
  if (!o.run.record_path.empty()) log << "recorded " << o.run.record_path << " (replay: isotouch replay " << o.run.record_path << ")\n";
  if (folder) {
    session::clear_last_words();  // the folder's final status follows
    write_live_outputs(scene, setup, tracer, s, seconds, device.description, *folder, log);
  }
  // Stopped by a signal: the recording is complete, but the run did not run its course.
  if (session::stop_signal() != 0) return exit_code::signalled(session::stop_signal());
  if (s.faults > 0) return exit_code::kServoFaults;
  return device_lost ? exit_code::kDeviceLost : exit_code::kOk;
}

}  // namespace

int run_live(const io::Scene& scene, const LiveOptions& o, std::ostream& log) {
  if (o.run.out_dir.empty()) return run_live_in(scene, o, nullptr, log);
  // --out: the folder is made and locked first (a second run into it is refused at once);
  // it ends "complete", "interrupted" or "failed", never "running".
  io::RunFolder folder(o.run.out_dir, scene.file, scene.name);
  const LastWordsWhileRunning last_words(scene, o.run.out_dir);
  try {
    return run_live_in(scene, o, &folder, log);
  } catch (const std::exception& e) {
    folder.mark_failed(e.what());
    throw;
  }
}

}  // namespace isotouch::run
