// app_setup.cpp - isotouch-sculpt's set-up steps, in run_sculpt's order (sculpt_app.h).

#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

// --- set-up ------------------------------------------------------------------------------

namespace {

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

}  // namespace

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
  const materials::LabelVolume& lv = labels.emplace(materials::load_label_volume(scene.materials, vol));
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
  if (labels) {  // each voxel's material colour over the grey, each material's boundary in its colour
    MaterialsControl mc;
    for (std::size_t i = 0; i < labels->materials.size(); ++i) {
      const materials::Material& m = labels->materials[i];
      mc.rows.push_back({m.name, m.color, true, m.critical, m.margin_mm, m.stiffness_n_per_m, long(labels->voxels[i + 1])});
    }
    slices.set_labels(&labels->ids, &vol.voxels, std::move(mc));
  }
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

}  // namespace isotouch::sculpt::detail
