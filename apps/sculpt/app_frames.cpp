// app_frames.cpp - isotouch-sculpt's frame loop: a frame's steps, moving frames and the still
// view's refinement, the slice views, the tools, the edits, the picture and the panels (sculpt_app.h).

#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

namespace {

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

}  // namespace

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
  panels->build(tool, iso_ctl, slices.control(), slices.materials(), panel, overlay);
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

}  // namespace isotouch::sculpt::detail
