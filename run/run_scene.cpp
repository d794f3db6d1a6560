#include "isotouch/run/run_scene.h"
#include <csignal>
#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>
#include "isotouch/run/edit_driver.h"
#include "isotouch/servo/hri.h"
#include "isotouch/session/live_session.h"
#include "isotouch/run/names.h"
#include "isotouch/run/overview.h"
#include "isotouch/run/picture.h"
#include "isotouch/run/run_outputs.h"
#include "isotouch/run/run_report.h"
#include "isotouch/session/stop_signal.h"
#include "isotouch/sim/stability.h"
#include "isotouch/run/text.h"
#include "isotouch/run/trace_csv.h"
#include "isotouch/run/trace_figures.h"
#include "isotouch/servo/triple_buffer.h"

namespace isotouch::run {
namespace fs = std::filesystem;
namespace {

std::function<void(long, long)> servo_progress(const RunOptions& opt) {
  const bool tty = opt.progress && ::isatty(STDERR_FILENO);
  auto last_quarter = std::make_shared<int>(-1);
  return [tty, last_quarter, show = opt.progress](long k, long total) {
    throw_if_stop_requested("servo simulation, tick " + std::to_string(k) + " of " + std::to_string(total));
    if (!show) return;
    const int pct = int(100 * k / total);
    if (tty) {
      std::cerr << "\rservo    [" << std::string(std::size_t(pct / 4), '#')
                << std::string(std::size_t(25 - pct / 4), '.') << "] " << std::setw(3) << pct << "%  "
                << k << "/" << total << " ticks" << (k == total ? "\n" : "") << std::flush;
    } else if (pct / 25 != *last_quarter) {  // not a terminal: a line per quarter
      *last_quarter = pct / 25;
      std::cerr << "servo    " << k << "/" << total << " ticks (" << pct << "%)\n";
    }
  };
}

// script.lift_retrace: the tool's path while pressed (the proxy from t_press on, a point each
// time it moved 0.05 mm from the last one kept), handed to the script before the first tick
// reads a lift target (a tick reads the hand's target one period ahead).
std::function<void(sim::TraceRow&)> lift_retracer(sim::TouchScript& script, double rate_hz) {
  auto path = std::make_shared<std::vector<Vec3>>();
  auto done = std::make_shared<bool>(false);
  return [&script, path, done, period = 1.0 / rate_hz](sim::TraceRow& row) {
    if (*done || row.t_s < script.t_press) return;
    if (path->empty() || core::norm(row.vhip_m - path->back()) >= 5e-5) path->push_back(row.vhip_m);
    if (row.t_s + 2.0 * period >= script.t_lift) {
      script.retrace_lift(*path);
      *done = true;
    }
  };
}

// The scene in the live session's simulated mode: the servo, the edits and the recorder
// clocked in simulated time on this thread (what the app and `run --live` run on threads).
std::vector<sim::TraceRow> simulate(const Scene& scene, SceneSetup& setup, const RunOptions& opt,
                                    servo::TripleBuffer<core::SampleField>& published, std::optional<EditDriver>& edits) {
  const servo::HriParams& hp = setup.hri;
  const servo::WorkspaceTransform& xf = setup.world_T_device;
  const sim::TouchScript& script = setup.script;
  Vec3 start_w, v0;
  script.at(0.0, start_w, v0);
  sim::SimDevice device(scene.device, xf.to_device(start_w));
  servo::HriRenderer renderer(hp);
  session::LiveSessionConfig lc;
  lc.servo.rate_hz = hp.rate_hz;
  lc.servo.force_limit_n = hp.force_limit_n;
  lc.servo.world_T_device = xf;
  if (edits) {
    lc.drill = edits->drill();
    lc.on_applied = [&edits](const EditEvent& e, const EditOutcome& o, session::EditSource src) { edits->on_applied(e, o, src); };
  }
  if (!opt.record_path.empty()) {
    lc.record_path = opt.record_path;
    lc.record_header = recording_header(scene, setup);
  }
  session::LiveSession live(setup.session.get(), published, renderer, std::move(lc));
  session::SimulatedRun sr;
  sr.device = &device;
  sr.script = &script;
  sr.world_T_device = xf;
  std::function<void(sim::TraceRow&)> retrace;
  if (setup.script.lift_retrace) retrace = lift_retracer(setup.script, hp.rate_hz);
  if (edits) sr.button_down = scene.edits.button_down;
  if (edits || retrace)
    sr.after_tick = [&edits, &live, &retrace](long k, sim::TraceRow& row) {
      if (edits) (*edits)(live, k, row);
      if (retrace) retrace(row);
    };
  sr.progress = servo_progress(opt);
  std::vector<sim::TraceRow> trace = live.run_simulated(sr);
  live.stop();  // the recording: end record, fsync, rename
  RunMetrics& m = setup.metrics;
  m.edit_period_s = hp.edit_period_s;
  m.edit_ease_ticks = long(renderer.edit_eased_ticks());
  m.edit_ease_max_rate_n_s = renderer.edit_ease_max_rate();
  m.release_fade_ticks = long(renderer.release_fade_ticks());
  m.device_clipped_ticks = device.saturated_commands();
  return trace;
}

// The run's picture is one GPU submission that cannot be cut short (seconds to tens of
// seconds on a CPU device such as lavapipe): it is drawn on its own thread while this one
// watches for a stop. Asked to stop, the run marks its folder "interrupted" and ends the
// process at once (as a second Ctrl+C would) instead of waiting for the picture.
RunPicture picture_or_stop(const std::function<RunPicture()>& draw, const RunFolder& folder, std::ostream& log) {
  std::packaged_task<RunPicture()> task(draw);
  std::future<RunPicture> done = task.get_future();
  std::thread drawer(std::move(task));
  while (done.wait_for(std::chrono::milliseconds(20)) != std::future_status::ready) {
    if (const int sig = session::stop_signal(); sig != 0) {
      const std::string stage = "outputs (trace and plots written; the picture abandoned)";
      if (folder.mark_interrupted(stage, sig))
        log << "\ninterrupted (" << (sig == SIGTERM ? "SIGTERM" : "SIGINT") << ") during " << stage << ": "
            << (fs::path(folder.dir()) / "summary.json").string() << " says \"status\": \"interrupted\"\n";
      log.flush();
      std::cerr.flush();
      session::clear_last_words();  // the folder's status is the one just written
      session::end_process_now(sig);
    }
  }
  drawer.join();
  return done.get();
}

RunMetrics run_scene_steps(const Scene& scene, const RunOptions& opt, const RunFolder& folder, std::ostream& log) {
  throw_if_stop_requested("start");
  SceneSetup setup = setup_scene(scene, opt, log);
  throw_if_stop_requested("engine set-up (samples computed, servo not started)");
  RunMetrics& m = setup.metrics;
  const engine::Volume& vol = setup.volume;
  const std::shared_ptr<const core::SampleField> field = setup.first;
  const servo::HriParams& hp = setup.hri;
  const sim::TouchScript& script = setup.script;
  // Colgate and Schenkel's passivity bound for the scene's K, B and rate, with the damping
  // at the handle b = device + hand damping [N s/m]: a stiffer wall may buzz (K = 1e6 N/m
  // on the sphere at 1 kHz: 152 on/off flips). Warned in the log and reported.
  m.k_bound_n_per_m = sim::colgate_k_max(scene.device.damping_n_s_per_m + scene.device.hand_damping_n_s_per_m,
                                           hp.damping_n_s_per_m, 1.0 / hp.rate_hz);
  m.k_above_bound = !(hp.stiffness_n_per_m <= m.k_bound_n_per_m);
  if (m.k_above_bound)
    log << "warning: stiffness " << hp.stiffness_n_per_m << " N/m is above the Colgate-Schenkel bound K_max = "
        << "2 (b - |B|) / T = " << m.k_bound_n_per_m << " N/m (b = device + hand damping, B = servo damping, "
        << "T = 1 / rate_hz): the contact may buzz; lower K or B, or raise the rate\n";

  // Publish the samples: the servo reads them through the one publication point.
  servo::TripleBuffer<core::SampleField> published;
  published.publish(field);
  std::optional<EditDriver> edits;
  if (setup.session) edits.emplace(scene, setup);
  const std::vector<sim::TraceRow> trace = simulate(scene, setup, opt, published, edits);
  const auto [found, raw_found] = trace_figures(trace, setup, edits ? &*edits : nullptr, m);
  if (m.contact_ticks == 0)
    log << "no contact: the probe never touched the isosurface in " << m.ticks
        << " ticks; the surface error is not known (null in summary.json)\n";
  log << "steps    |F| between contact ticks " << fmt(m.max_force_step_n, 4) << " N, F vector "
      << fmt(m.max_force_vector_step_n, 4) << " N (t = " << fmt(m.max_force_vector_step_t_s, 5) << " s), release "
      << fmt(m.max_release_step_n, 4) << " N (t = " << fmt(m.max_release_step_t_s, 5) << " s), any ticks "
      << fmt(m.max_any_step_n, 4) << " N (t = " << fmt(m.max_any_step_t_s, 5) << " s)\n";

  // 6. Outputs, each written whole or not at all (RunFolder has made and locked the folder).
  const std::string dir = opt.out_dir;
  throw_if_stop_requested("outputs (servo finished, no file written yet)");
  if (scene.write_trace) write_file_atomic((fs::path(dir) / "trace.csv").string(), trace_csv(trace, vol));
  if (scene.write_trace && scene.draw_plots) m.plots_drawn = draw_plots(scene, dir, script, m.plot_note);
  else m.plot_note = "plots turned off in the scene (outputs.plots / outputs.trace_csv)";
  throw_if_stop_requested("outputs (trace and plots written)");
  if (scene.draw_plots) {
    // The run's picture (ray-cast on the same Vulkan device); never throws.
    // With edits the path is thinned (thin_path): the same picture serves as before.png.
    std::vector<sim::TraceRow> thinned;
    if (edits) thinned = thin_path(trace);
    const std::vector<sim::TraceRow>& path = edits ? thinned : trace;
    const RunPicture pic = picture_or_stop(
        [&] {
          return render_run_picture(scene, vol, *field, path, (fs::path(dir) / "surface.png").string(),
                                    setup.vk.get(), setup.device);
        },
        folder, log);
    m.picture_drawn = pic.error.empty();
    m.picture_note = m.picture_drawn ? pic.caption : pic.error;
    if (!m.picture_drawn) log << "picture  not drawn: " << pic.error << "\n";
    else log << "picture  surface.png, up: " << pic.up << "\n";
    // The overview: the whole object upright with the path on it (the picture a user recognises).
    const RunPicture over = picture_or_stop(
        [&] {
          return render_overview(scene, vol, *field, path, (fs::path(dir) / kOverviewFile).string(), setup.vk.get(),
                                 setup.device);
        },
        folder, log);
    m.overview_drawn = over.error.empty();
    m.overview_note = overview_sentence(over);
    log << "picture  " << m.overview_note << "\n";
  }
  throw_if_stop_requested("outputs (trace, plots and picture written)");
  if (edits) finish_edits(scene, setup, *edits, trace, dir, opt.mesh_units, m, log);
  throw_if_stop_requested("outputs (all but summary.json and report.md written)");

  const std::string summary_text = summary_json(scene, setup, m, found, raw_found, edits.has_value()).dump(2) + "\n";
  write_file_atomic((fs::path(dir) / "report.md").string(), report_markdown(scene, setup, m, found, raw_found, edits.has_value()));
  // Last: "complete" only once every other output is whole (a second signal no longer
  // overwrites it).
  session::clear_last_words();
  write_file_atomic((fs::path(dir) / "summary.json").string(), summary_text);
  return m;
}

}  // namespace

namespace {
// summary.json as a second SIGINT / SIGTERM leaves it when it ends the process at once.
std::string killed_summary(const Scene& scene, const char* signal) {
  nlohmann::ordered_json j;
  j["status"] = "interrupted";
  j["scene"] = {{"file", scene.file}, {"name", scene.name}};
  j["signal"] = signal;
  j["stage"] = std::string("not known: a second ") + signal + " ended the process at once";
  j["note"] = "the run was stopped before it finished: the files in the folder are whole (each is written whole or "
              "not at all) but the figures of a complete run (report.md, the rest of summary.json) were not written";
  return j.dump(2) + "\n";
}
}  // namespace

LastWordsWhileRunning::LastWordsWhileRunning(const Scene& scene, const std::string& dir) {
  session::set_last_words((fs::path(dir) / "summary.json").string(), killed_summary(scene, "SIGINT"),
                          killed_summary(scene, "SIGTERM"));
}

LastWordsWhileRunning::~LastWordsWhileRunning() { session::clear_last_words(); }

RunMetrics run_scene(const Scene& scene, const RunOptions& opt, std::ostream& log) {
  RunFolder folder(opt.out_dir, scene.file, scene.name);
  const LastWordsWhileRunning last_words(scene, opt.out_dir);
  try {
    return run_scene_steps(scene, opt, folder, log);
  } catch (const Interrupted& e) {
    if (folder.mark_interrupted(e.stage, e.signal))
      log << "\ninterrupted (" << (e.signal == SIGTERM ? "SIGTERM" : "SIGINT") << ") during " << e.stage
          << ": " << (fs::path(opt.out_dir) / "summary.json").string() << " says \"status\": \"interrupted\"\n";
    throw;
  } catch (const std::exception& e) {
    folder.mark_failed(e.what());
    throw;
  }
}

}  // namespace isotouch::run
