// scene_py.cpp - scenes and recordings from Python: `isotouch run`'s job on a scene file
// (its run folder read back in python/isotouch/files.py) and a recording read into arrays.
#include <memory>
#include <sstream>

#include "isotouch/io/record.h"
#include "isotouch/io/scene.h"
#include "isotouch/python/common.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/servo/hri.h"

namespace isotouch::python {
namespace {

/// `isotouch run SCENE --out DIR` without the command line: the same job, the same files.
std::string run_scene(const std::string& scene_path, const std::string& out_dir, const std::string& device,
                      const std::string& record) {
  py::gil_scoped_release nogil;
  const io::Scene scene = io::load_scene(scene_path);
  run::RunOptions o;
  o.out_dir = out_dir;
  o.device = device;
  o.progress = false;
  o.record_path = record;
  std::ostringstream log;
  run::run_scene(scene, o, log);  // makes, locks and marks the folder (failed on a throw)
  return log.str();
}

/// What `isotouch run` builds before its first tick (run::setup_scene): the volume, the first
/// published snapshot, the renderer's parameters.
py::dict scene_setup(const std::string& scene_path, const std::string& device) {
  std::shared_ptr<run::SceneSetup> s;
  {
    py::gil_scoped_release nogil;
    const io::Scene scene = io::load_scene(scene_path);
    run::RunOptions o;
    o.device = device;
    o.progress = false;
    std::ostringstream log;
    s = std::make_shared<run::SceneSetup>(run::setup_scene(scene, o, log));
  }
  py::dict d;
  d["volume"] = std::make_shared<engine::Volume>(s->volume);
  d["field"] = std::const_pointer_cast<core::SampleField>(s->first);
  d["truth"] = std::const_pointer_cast<core::SampleField>(s->truth);
  d["hri"] = s->hri;
  d["device"] = s->device;
  d["script_duration_s"] = s->script.duration_s;
  return d;
}

py::dict ticks_dict(const std::vector<io::RecordedTick>& ticks) {
  const auto n = py::ssize_t(ticks.size());
  py::array_t<double> t(n), dt(n), hip({n, py::ssize_t(3)}), force({n, py::ssize_t(3)}), vhip({n, py::ssize_t(3)});
  py::array_t<std::uint64_t> version(n);
  py::array_t<bool> button(n), fault(n), held(n), reset(n);
  for (py::ssize_t k = 0; k < n; ++k) {
    const io::RecordedTick& r = ticks[std::size_t(k)];
    t.mutable_at(k) = r.t_s;
    dt.mutable_at(k) = r.dt_s;
    for (int i = 0; i < 3; ++i) {
      hip.mutable_at(k, i) = (&r.hip_m.x)[i];
      force.mutable_at(k, i) = (&r.force_n.x)[i];
      vhip.mutable_at(k, i) = (&r.vhip_m.x)[i];
    }
    version.mutable_at(k) = r.version;
    button.mutable_at(k) = r.button;
    fault.mutable_at(k) = r.fault;
    held.mutable_at(k) = r.held;
    reset.mutable_at(k) = r.reset;
  }
  py::dict d;
  d["t"] = t, d["dt"] = dt, d["hip"] = hip, d["force"] = force, d["vhip"] = vhip, d["version"] = version;
  d["button"] = button, d["fault"] = fault, d["held"] = held, d["reset"] = reset;
  return d;
}

py::dict edits_dict(const std::vector<session::EditEvent>& edits) {
  const auto n = py::ssize_t(edits.size());
  py::array_t<long> tick(n);
  py::array_t<double> t(n), centre({n, py::ssize_t(3)}), radius(n), strength(n), force(n);
  py::list kind, brush;
  for (py::ssize_t k = 0; k < n; ++k) {
    const session::EditEvent& e = edits[std::size_t(k)];
    kind.append(session::to_string(e.kind));
    brush.append(e.kind == session::EditEvent::Kind::kBrush ? session::to_string(e.brush.kind) : "");
    tick.mutable_at(k) = e.tick;
    t.mutable_at(k) = e.t_s;
    for (int i = 0; i < 3; ++i) centre.mutable_at(k, i) = (&e.brush.centre_m.x)[i];
    radius.mutable_at(k) = e.brush.radius_m;
    strength.mutable_at(k) = e.brush.strength;
    force.mutable_at(k) = e.brush.force_n;
  }
  py::dict d;
  d["kind"] = kind, d["brush"] = brush, d["tick"] = tick, d["t"] = t, d["centre"] = centre;
  d["radius"] = radius, d["strength"] = strength, d["force_n"] = force;
  return d;
}

py::dict load_recording(const std::string& path, bool allow_incomplete) {
  io::Recording r;
  {
    py::gil_scoped_release nogil;
    r = io::load_recording(path, allow_incomplete);
  }
  py::dict d;
  d["format_version"] = r.format_version;
  d["complete"] = r.complete;
  d["scene_path"] = r.scene_path;
  d["scene_text"] = r.scene_text;
  d["rate_hz"] = r.rate_hz;
  d["volume_crc32"] = r.volume_crc32 ? py::object(py::int_(*r.volume_crc32)) : py::object(py::none());
  d["ticks"] = ticks_dict(r.ticks);
  d["edits"] = edits_dict(r.edits);
  return d;
}

}  // namespace

void bind_scene(py::module_& m) {
  m.def("run_scene", &run_scene, py::arg("scene"), py::arg("out"), py::arg("device") = "cpu",
        py::arg("record") = "", R"(Run a scene as `isotouch run SCENE --out OUT [--device D] [--record FILE]`
does (the same job and files: trace.csv, summary.json, report.md, ...). GIL released. Returns
the log text; read the folder with isotouch.read_run_folder(out). Raises SceneError,
VolumeError with the CLI's messages.)");
  m.def("scene_setup", &scene_setup, py::arg("scene"), py::arg("device") = "cpu",
        R"(A scene made ready as `isotouch run` makes it, as a dict: 'volume' (a copy), 'field' (the first
published snapshot, what tick 0 reads), 'truth' (dense CPU reference samples), 'hri' (HriParams),
'device', 'script_duration_s' [s].)");
  m.def("load_recording", &load_recording, py::arg("path"), py::arg("allow_incomplete") = false,
        R"(A recording (`run --record`, `run --live --record`, a LiveSession's) as a dict: header fields,
'ticks' (arrays: t, dt [s], hip, force, vhip (N, 3) [m, N; grid-world], version, button, fault,
held, reset) and 'edits' (kind, brush, tick, t, centre (M, 3) [m], radius [m], strength, force_n).
Raises RecordingError naming the file, line and field.)");
}

}  // namespace isotouch::python
