// app_report.cpp - isotouch-sculpt's end: finish, the stats, the verdicts, the floor (sculpt_app.h).

#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

// --- the end: the report -------------------------------------------------------------------

namespace {

/// "stats    WHAT: n N, median M ms, p95 P ms, max X ms" (or none).
void stats_line(std::ostream& log, const char* what, const std::vector<double>& v) {
  if (v.empty()) {
    log << "stats    " << what << ": none\n";
    return;
  }
  log << "stats    " << what << ": n " << v.size() << ", median " << fixed(eval::median(v), 2) << " ms, p95 "
      << fixed(eval::percentile(v, 0.95), 2) << " ms, max " << fixed(*std::max_element(v.begin(), v.end()), 2) << " ms\n";
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

}  // namespace isotouch::sculpt::detail

namespace isotouch::sculpt {

bool servo_misses_pass(long sculpt_missed, long sculpt_ticks, long alone_missed, long alone_ticks, double& allowed) {
  const double ref = alone_ticks > 0 ? double(alone_missed) * double(sculpt_ticks) / double(alone_ticks) : 0.0;
  allowed = ref + 3.0 * std::sqrt(ref);
  return double(sculpt_missed) <= allowed;
}

}  // namespace isotouch::sculpt
