// replay.cpp - a recording played back through the same renderer and edit pipeline, every
// force compared bit for bit (see replay.h).
#include "isotouch/run/replay.h"

#include <bit>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "isotouch/session/brush.h"
#include "isotouch/io/files.h"
#include "isotouch/run/names.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/io/scene.h"

namespace isotouch::run {
using core::to_string;
using io::load_recording;
using io::volume_crc32;
using io::write_file_atomic;
using session::to_string;
using io::RecordedTick;
using io::Recording;
using io::RecordingError;
using io::Scene;
using io::SceneError;
using session::EditSession;
namespace {

namespace fs = std::filesystem;

std::string num(double v) {
  std::ostringstream s;
  s << std::setprecision(17) << v;
  return s.str();
}
std::string vec(const core::Vec3& v) {
  std::ostringstream s;  // one stream (GCC 12 warns falsely on "(" + std::string&&)
  s << std::setprecision(17) << '(' << v.x << ", " << v.y << ", " << v.z << ')';
  return s.str();
}

bool same_bits(const core::Vec3& a, const core::Vec3& b) {
  return std::bit_cast<std::uint64_t>(a.x) == std::bit_cast<std::uint64_t>(b.x) &&
         std::bit_cast<std::uint64_t>(a.y) == std::bit_cast<std::uint64_t>(b.y) &&
         std::bit_cast<std::uint64_t>(a.z) == std::bit_cast<std::uint64_t>(b.z);
}

/// The recorded scene: the text the recording carries, parsed as if it were still at the
/// recorded path (io::recorded_scene_path), so that a relative volume path resolves against
/// the scene's folder at record time; the file itself may have changed, moved or gone. The
/// volume is checked by its CRC-32 once loaded.
Scene recorded_scene(const Recording& rec, const std::string& name, const std::string& dir) {
  const std::string path = io::recorded_scene_path(rec, dir);
  try {
    return io::parse_scene(rec.scene_text, path);
  } catch (const SceneError& e) {
    throw ReplayInputError(name + ": the scene it carries (recorded from " + path + ") is refused: " + e.what());
  }
}

/// The sculpting app's edit session (the recording's edit_session), in place of the scene's:
/// the same brushes (GPU or CPU reference), undo limit, live field and edit ease period, its
/// first snapshot the one the servo read first.
void use_recorded_edit_session(const Recording& rec, SceneSetup& setup) {
  if (!rec.edit_session) return;
  engine::VulkanContext* vk = rec.edit_session->gpu_brushes ? setup.vk.get() : nullptr;
  setup.session = std::make_unique<EditSession>(engine::Volume(setup.volume), vk, setup.live,
                                                rec.edit_session->history_limit_mib);
  setup.first = setup.session->current();
  if (rec.edit_session->edit_period_s > 0) setup.hri.edit_period_s = rec.edit_session->edit_period_s;
}

/// One row of the replay's trace.csv (grid-world frame, as the renderer sees it).
void trace_row(std::ostringstream& csv, long k, const RecordedTick& t, const core::Vec3& f, double df,
               std::uint64_t version, long edits) {
  csv << k << ',' << t.t_s << ',' << t.hip_m.x << ',' << t.hip_m.y << ',' << t.hip_m.z << ',' << t.force_n.x << ','
      << t.force_n.y << ',' << t.force_n.z << ',' << f.x << ',' << f.y << ',' << f.z << ',' << df << ','
      << int(same_bits(t.force_n, f)) << ',' << version << ',' << edits << '\n';
}

/// Applies tick k's recorded edits (events [e, end) with tick == k); returns the new e.
std::size_t apply_edits(const Recording& rec, std::size_t e, long k, EditSession& session,
                        servo::TripleBuffer<core::SampleField>& buf, ReplayResult& r, const std::string& name) {
  for (; e < rec.edits.size() && rec.edits[e].tick == k; ++e) {
    try {
      r.publications += session.apply(rec.edits[e], &buf).published;
    } catch (const std::exception& ex) {
      throw ReplayInputError(name + ": edit " + std::to_string(e) + " (" + to_string(rec.edits[e].kind) + ", tick " +
                             std::to_string(k) + ") was refused by the edit pipeline: " + ex.what());
    }
    ++r.edits;
  }
  return e;
}

/// Format 3: applies recorded edits in order while the session's snapshot is older than
/// `version` (the one the next tick read live).
std::size_t apply_edits_upto(const Recording& rec, std::size_t e, std::uint64_t version, EditSession& session,
                             servo::TripleBuffer<core::SampleField>& buf, ReplayResult& r, const std::string& name) {
  for (; e < rec.edits.size() && session.current()->version < version; ++e) {
    try {
      r.publications += session.apply(rec.edits[e], &buf).published;
    } catch (const std::exception& ex) {
      throw ReplayInputError(name + ": edit " + std::to_string(e) + " (" + to_string(rec.edits[e].kind) +
                             ") was refused by the edit pipeline: " + ex.what());
    }
    ++r.edits;
  }
  return e;
}

/// The renderer's answer to recorded tick `t`, as the servo gave it: simulated runs at the
/// nominal period (as run_headless); live ones at the measured dt, reset where the servo
/// reset it, and not ticked where it held (zero force, no VHIP: what the servo recorded).
servo::HriTick replay_tick(servo::HriRenderer& renderer, const core::SampleField& field, const RecordedTick& t, bool live) {
  if (!live) return renderer.tick(field, t.hip_m);
  if (t.held) return servo::HriTick{};
  if (t.reset) renderer.reset();
  return renderer.tick(field, t.hip_m, t.dt_s);
}

}  // namespace

ReplayResult replay_recording(const Recording& rec, const ReplayOptions& opt, std::ostream& log) {
  const std::string& name = opt.name;
  const Scene scene = recorded_scene(rec, name, opt.recording_dir);
  RunOptions ropt;
  ropt.device = opt.device;
  ropt.progress = false;
  SceneSetup setup = setup_scene(scene, ropt, log);
  use_recorded_edit_session(rec, setup);
  if (std::bit_cast<std::uint64_t>(setup.hri.rate_hz) != std::bit_cast<std::uint64_t>(rec.rate_hz))
    throw ReplayInputError(name + ": recorded at " + num(rec.rate_hz) + " Hz, the scene's servo runs at " +
                           num(setup.hri.rate_hz) + " Hz");
  if (rec.volume_crc32 && *rec.volume_crc32 != volume_crc32(setup.volume))
    throw ReplayInputError(name + ": the volume " + setup.volume.path + " changed since it was recorded (CRC-32 of its voxels " +
                           std::to_string(volume_crc32(setup.volume)) + " now, " + std::to_string(*rec.volume_crc32) +
                           " recorded): a replay would not be of the same run");
  if (!rec.edits.empty() && !setup.session)
    throw ReplayInputError(name + ": the recording has " + std::to_string(rec.edits.size()) +
                           " edits but the scene " + rec.scene_path +
                           " has no \"edits\" section and the recording no edit_session");

  servo::TripleBuffer<core::SampleField> buf;
  buf.publish(setup.first);
  servo::HriRenderer renderer(setup.hri);
  ReplayResult r;
  std::ostringstream csv;
  const bool trace = !opt.out_dir.empty();
  if (trace) {
    csv << "tick,t_s,hip_x_m,hip_y_m,hip_z_m,f_rec_x_n,f_rec_y_n,f_rec_z_n,f_x_n,f_y_n,f_z_n,df_n,identical,"
           "version,edits\n"
        << std::setprecision(17);
  }
  const long n = long(rec.ticks.size());
  const bool live = rec.format_version >= 3;
  std::size_t e = 0;
  int last_decile = 0;
  for (long k = 0; k < n; ++k) {
    const RecordedTick& t = rec.ticks[std::size_t(k)];
    // A live recording (format 3): the edits applied before this tick read its snapshot,
    // in the recorded order, up to the version the tick read live.
    if (live && setup.session) {
      e = apply_edits_upto(rec, e, t.version, *setup.session, buf, r, name);
      // A cut recording (a killed session's FILE.part): the recorder writes an edit after the
      // ticks it took with it, and the edit thread logs an edit just after publishing it, so
      // the last chunk's ticks may read a snapshot whose edit was written after the cut. With
      // every recorded edit applied and the snapshot still older, the rest is not compared
      // (in a complete recording it is: a difference).
      if (!rec.complete && e == rec.edits.size() && setup.session->current()->version < t.version) {
        r.cut_ticks = n - k;
        break;
      }
    }
    const core::SampleField* field = buf.acquire();
    const servo::HriTick out = replay_tick(renderer, *field, t, live);
    const double df = core::norm(out.force_n - t.force_n);
    const bool same_force = same_bits(out.force_n, t.force_n);
    const bool checked = rec.format_version >= 2;  // format 1 recorded the force only
    const bool same_vhip = !checked || same_bits(out.vhip_m, t.vhip_m);
    const bool same_version = !checked || field->version == t.version;
    const bool same_fault = !checked || out.fault == t.fault;
    const bool same = same_force && same_vhip && same_version && same_fault;
    if (!same) {
      if (r.first_diff_tick < 0) {
        r.first_diff_tick = k;
        r.first_diff_t_s = t.t_s;
        r.first_recorded_n = t.force_n;
        r.first_replayed_n = out.force_n;
        r.first_recorded_vhip_m = t.vhip_m;
        r.first_replayed_vhip_m = out.vhip_m;
        r.first_recorded_version = t.version;
        r.first_replayed_version = field->version;
        for (const auto& [differs, what] : {std::pair{!same_force, "force"}, std::pair{!same_vhip, "VHIP"},
                                            std::pair{!same_version, "snapshot version"},
                                            std::pair{!same_fault, out.fault ? "fault (the replayed HIP is a fault)" : "fault"}})
          if (differs) r.first_diff_what += (r.first_diff_what.empty() ? "" : ", ") + std::string(what);
      }
      ++r.differing_ticks;
      if (!same_force) r.max_df_n = std::max(r.max_df_n, std::isnan(df) ? INFINITY : df);
    }
    const std::uint64_t version = field->version;
    const long before = r.edits;
    if (setup.session && !live) e = apply_edits(rec, e, k, *setup.session, buf, r, name);
    if (trace) trace_row(csv, k, t, out.force_n, df, version, r.edits - before);
    ++r.ticks;
    if (opt.progress && n >= 1000 && int(10 * (k + 1) / n) > last_decile) {
      last_decile = int(10 * (k + 1) / n);
      std::cerr << "replay   " << (k + 1) << "/" << n << " ticks (" << 10 * last_decile << "%), " << r.differing_ticks
                << " differing\n";
    }
  }
  // Live: edits applied after the last recorded tick read anything (they change no tick).
  if (live && setup.session) apply_edits_upto(rec, e, UINT64_MAX, *setup.session, buf, r, name);
  if (trace) write_file_atomic((fs::path(opt.out_dir) / "trace.csv").string(), csv.str());
  return r;
}

std::string replay_verdict(const ReplayResult& r, int rec_format) {
  std::ostringstream out;
  if (r.identical()) {
    out << "IDENTICAL: every force" << (rec_format >= 2 ? ", VHIP and snapshot version" : "")
        << " equals the recorded one bit for bit" << (rec_format >= 2 ? "" : " (format 1 recording: forces only)")
        << "\n";
    return out.str();
  }
  out << std::setprecision(17) << "DIFFERENT: " << r.differing_ticks << " of " << r.ticks << " ticks differ; first at tick "
      << r.first_diff_tick << " (t = " << r.first_diff_t_s << " s) in the " << r.first_diff_what
      << ": force recorded " << vec(r.first_recorded_n) << " N, replayed " << vec(r.first_replayed_n) << " N";
  if (rec_format >= 2)
    out << "; VHIP recorded " << vec(r.first_recorded_vhip_m) << " m, replayed " << vec(r.first_replayed_vhip_m)
        << " m; snapshot version recorded " << r.first_recorded_version << ", replayed " << r.first_replayed_version;
  out << "\n";
  return out.str();
}

}  // namespace isotouch::run
