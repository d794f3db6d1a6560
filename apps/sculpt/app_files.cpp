// app_files.cpp - isotouch-sculpt's save, export, dropped files and the isovalue (sculpt_app.h).

#include "isotouch/apps/sculpt/sculpt_app.h"

namespace isotouch::sculpt::detail {

namespace {

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

}  // namespace

// --- save, export, dropped files, the isovalue ---------------------------------------------

/// The volume as the picture shows it (the applied edits).
engine::Volume Sculpt::edited_volume() {
  engine::Volume out = vol;
  std::lock_guard<std::mutex> lock(feed.mu);
  out.voxels = feed.values;
  return out;
}

namespace {

/// Where the edited label map goes beside a saved volume: its name without the volume's
/// extension (.vdb, .nrrd, .mha, .nii, .nii.gz), then ".seg.nrrd".
std::string seg_nrrd_beside(const std::string& volume_path) {
  std::string stem = volume_path;
  for (const char* ext : {".nii.gz", ".vdb", ".nrrd", ".mha", ".nii"}) {
    const std::size_t n = std::strlen(ext);
    if (stem.size() > n && stem.compare(stem.size() - n, n, ext) == 0) {
      stem.resize(stem.size() - n);
      break;
    }
  }
  return stem + ".seg.nrrd";
}

}  // namespace

void Sculpt::save(const std::string& path) {
  const engine::Volume out = edited_volume();
  try {
    io::save_any_volume(out, path, io::SaveVdbOptions{});  // the format the name asks for
    status = "saved " + path;
    if (labels) {  // the edited label map beside it, for 3D Slicer: removed voxels 0
      const std::string seg = seg_nrrd_beside(path);
      materials::write_seg_nrrd(seg, materials::edited_ids(labels->ids, vol.voxels, out.voxels, live.iso),
                                labels->materials, out);
      status += " and its label map " + seg;
    }
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

}  // namespace isotouch::sculpt::detail
