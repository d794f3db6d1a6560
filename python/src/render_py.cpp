// render_py.cpp - offline rendering from Python: the published samples (isotouch.Field), the
// renderers' parameters, HRI and the two baselines over an (N, 3) HIP trajectory in one call
// (GIL released), and the strokes `bench table1` replays.
#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <sstream>

#include "isotouch/core/sample_field.h"
#include "isotouch/engine/vk_context.h"
#include "isotouch/eval/sweep.h"
#include "isotouch/python/common.h"
#include "isotouch/python/interruptible.h"
#include "isotouch/python/params_arg.h"
#include "isotouch/servo/baselines.h"
#include "isotouch/servo/cpu_placement.h"
#include "isotouch/servo/hri.h"

#include <pybind11/stl.h>

namespace isotouch::python {
namespace {

using FieldPtr = std::shared_ptr<core::SampleField>;

/// A view of the dense samples: `comps` floats of each Sample from `first`, shape (nz, ny, nx[, comps]).
py::array sample_view(py::object self, int first, int comps) {
  const auto& f = self.cast<const core::SampleField&>();
  if (f.bricked() || f.samples.size() != f.grid.voxel_count())
    throw py::value_error("field: bricked; the sample arrays exist for dense fields only");
  const auto& d = f.grid.dims;
  const py::ssize_t s = sizeof(core::Sample);
  std::vector<py::ssize_t> shape{d[2], d[1], d[0]}, strides{s * d[1] * d[0], s * d[0], s};
  if (comps > 1) {
    shape.push_back(comps);
    strides.push_back(sizeof(float));
  }
  const float* base = &f.samples.data()->value + first;
  py::array a(py::dtype::of<float>(), shape, strides, base, self);
  py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;  // published: read only
  return a;
}

/// The data fields of a bound parameter object (its class's properties), in definition order.
py::list field_list(const py::object& o) {
  py::list out;
  const py::dict attrs = py::type::of(o).attr("__dict__");
  for (const auto& [key, value] : attrs)
    if (py::isinstance(value, py::module_::import("builtins").attr("property"))) out.append(key);
  return out;
}

std::string field_names(const py::object& o) {
  return py::str(", ").attr("join")(field_list(o)).cast<std::string>();
}

/// A parameter struct from keyword arguments: the defaults (tau NaN: not given), then each
/// keyword set as its attribute. @throws TypeError naming a keyword that is no field (and the fields there are).
template <class P>
P params_from_kwargs(const py::kwargs& kw) {
  P defaults{};
  if constexpr (requires { defaults.tau; }) defaults.tau = std::nan("");  // no isovalue until one is given
  py::object o = py::cast(defaults);
  for (const auto& [key, value] : kw) {
    const std::string k = py::str(key);
    if (!field_list(o).contains(key)) {
      const std::string type = py::str(py::type::of(o).attr("__name__"));
      throw py::type_error(type + "(): no field '" + k + "' (fields: " + field_names(o) + ")");
    }
    py::setattr(o, key, value);
  }
  return o.cast<P>();
}

/// "Name(tau=400.0, inside=InsideIs.above, ...)": every data field, as the constructor takes it.
template <class Class>
void def_params_repr(Class& c, const char* name) {
  c.def("__repr__", [name](py::object self) {
    std::string s = std::string(name) + "(";
    bool first = true;
    for (const py::handle f : field_list(self)) {
      const py::object v = py::getattr(self, f);
      const bool is_enum = py::hasattr(py::type::of(v), "__members__");  // InsideIs.above, not <InsideIs.above: 0>
      s += (first ? "" : ", ") + std::string(py::str(f)) + "=" + std::string(is_enum ? py::str(v) : py::repr(v));
      first = false;
    }
    return s + ")";
  });
}

/// One renderer for `algorithm` ("hri", "avila", "blezek") with `params` (HriParams for HRI,
/// BaselineParams for the baselines; None: the defaults) and the isovalue `tau` (params_arg).
std::unique_ptr<servo::Renderer> make_renderer(const std::string& algorithm, const py::object& params,
                                               std::optional<double> tau, const char* tau_name = "tau") {
  if (algorithm == "hri")
    return std::make_unique<servo::HriRenderer>(
        params_arg<servo::HriParams>(params, algorithm, "HriParams", tau, tau_name));
  if (algorithm == "avila" || algorithm == "blezek") {
    const auto p = params_arg<servo::BaselineParams>(params, algorithm, "BaselineParams", tau, tau_name);
    if (algorithm == "avila") return std::make_unique<servo::AvilaRenderer>(p);
    return std::make_unique<servo::BlezekRenderer>(p);
  }
  throw py::value_error("algorithm: '" + algorithm + "', must be 'hri', 'avila' or 'blezek'");
}

/// Where render() writes tick k: rows of the output arrays; the plane arrays only when asked.
/// The four flags of a tick lie side by side (one (N, 4) bool array, returned as its columns).
struct Outputs {
  double *force, *vhip;
  bool* flags;  // contact, plane_update, saturated, fault
  double *plane_n = nullptr, *plane_p = nullptr, *penetration = nullptr;
  bool* plane_valid = nullptr;
  static void put3(double* a, std::size_t k, const core::Vec3& v) {
    a[3 * k] = v.x;
    a[3 * k + 1] = v.y;
    a[3 * k + 2] = v.z;
  }
  void put(std::size_t k, const servo::HriTick& t) const {
    put3(force, k, t.force_n);
    put3(vhip, k, t.vhip_m);
    flags[4 * k] = t.contact;
    flags[4 * k + 1] = t.plane_update;
    flags[4 * k + 2] = t.saturated;
    flags[4 * k + 3] = t.fault;
    if (plane_n) {
      put3(plane_n, k, t.plane.n);
      put3(plane_p, k, t.plane.p);
      penetration[k] = t.penetration_m;
      plane_valid[k] = t.plane.valid;
    }
  }
};

/// An (N, 3) float64 array of `name` in the output dict, and where its data is.
double* points_out(py::dict& d, const char* name, py::ssize_t n) {
  py::array_t<double> a({n, py::ssize_t(3)});
  d[name] = a;
  return a.mutable_data();
}

template <class T>
T* column_out(py::dict& d, const char* name, py::ssize_t n) {
  py::array_t<T> a(n);
  d[name] = a;
  return a.mutable_data();
}

/// The (N, 4) flags array, each column in the dict under its name (views, no copy).
bool* flags_out(py::dict& d, py::ssize_t n) {
  py::array_t<bool> all({n, py::ssize_t(4)});
  bool* p = all.mutable_data();
  const char* names[] = {"contact", "plane_update", "saturated", "fault"};
  for (int j = 0; j < 4; ++j) d[names[j]] = py::array_t<bool>({n}, {py::ssize_t(4)}, p + j, all);
  return p;
}

py::dict render(const FieldPtr& field, const py::handle& hip, const std::string& algorithm, const py::object& params,
                double dt_s, bool planes, std::optional<double> tau) {
  // The caller's buffer when it is float64 (N, 3) C-contiguous. Not checked finite: a
  // non-finite HIP is the renderer's to refuse (zero force, fault), as on a device.
  const PointsIn hips = points_in(hip, "hip", false);
  std::unique_ptr<servo::Renderer> r = make_renderer(algorithm, params, tau);
  const auto n = py::ssize_t(hips.n);
  py::dict d;
  Outputs out{points_out(d, "force", n), points_out(d, "vhip", n), flags_out(d, n)};
  if (planes) {
    out.plane_n = points_out(d, "plane_n", n);
    out.plane_p = points_out(d, "plane_p", n);
    out.penetration = column_out<double>(d, "penetration", n);
    out.plane_valid = column_out<bool>(d, "plane_valid", n);
  }
  // In chunks of a few milliseconds, the GIL released in each; between them the signals:
  // Ctrl-C raises KeyboardInterrupt within a chunk, not at the end of the trajectory.
  constexpr std::size_t kChunkTicks = 16384;
  const core::SampleField& f = *field;
  for (std::size_t k0 = 0; k0 < hips.n; k0 += kChunkTicks) {
    {
      py::gil_scoped_release nogil;
      for (std::size_t k = k0; k < std::min(hips.n, k0 + kChunkTicks); ++k) out.put(k, r->tick(f, hips.at(k), dt_s));
    }
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
  }
  return d;
}

/// The C++ figure beside a Python timing: eval::median_ns_per_tick (what `bench table1` times)
/// over the same field and trajectory [ns per tick].
double cpp_ns_per_tick(const FieldPtr& field, const py::handle& hip, const std::string& algorithm,
                       const py::object& params, int warmup, int repetitions, std::optional<double> tau) {
  if (repetitions < 1 || warmup < 0) throw py::value_error("repetitions must be >= 1 and warmup >= 0");
  eval::SweepScene s;
  s.field = field;
  s.hip = points_arg(hip, "hip");
  if (s.hip.empty()) throw py::value_error("hip: no points");
  std::unique_ptr<servo::Renderer> r = make_renderer(algorithm, params, tau);
  // Ctrl-C stops it between two replays of the trajectory.
  return run_interruptible(
      [&](const std::atomic<bool>& cancel) { return eval::median_ns_per_tick(*r, s, warmup, repetitions, &cancel); });
}

/// The HRI parameters `bench table1` times on a stroke scene (reference_params with n = 5,
/// linear intersection, central-difference normal), in `variant`.
servo::HriParams table1_hri(const eval::SweepScene& s, servo::Variant variant) {
  servo::HriParams hp = eval::reference_params(s);
  hp.plane_update_period = 5;
  hp.intersection = servo::Intersection::kLinear;
  hp.normal = servo::NormalSource::kCentral;
  hp.variant = variant;
  return hp;
}

servo::BaselineParams table1_baseline(const eval::SweepScene& s) {
  servo::BaselineParams bp;
  bp.tau = s.tau;
  bp.inside = s.inside;
  bp.stiffness_n_per_m = s.stiffness_n_per_m;
  bp.force_limit_n = 1e3;
  return bp;
}

std::shared_ptr<eval::SweepScene> stroke_scene(const std::string& name, const std::string& device,
                                               std::optional<double> tau) {
  py::gil_scoped_release nogil;
  std::unique_ptr<engine::VulkanContext> vk;
  if (device != "cpu") {
    engine::ContextOptions co;
    co.device = device;
    auto ctx = engine::VulkanContext::create(co);
    if (!ctx) throw std::runtime_error("stroke_scene: no Vulkan device (" + ctx.error + "); device='cpu' runs the CPU reference");
    vk = std::move(*ctx.value);
  }
  std::ostringstream log;
  return std::make_shared<eval::SweepScene>(eval::prepare_sweep_scene(name, vk.get(), log, tau));
}

/// One task of the error-against-time sweep, as `isotouch report` measures it: the scene's
/// recorded stroke replayed through a fresh renderer, the error figures against the scene's
/// truth (eval::measure), and the mean tick from whole replays (median of `repetitions`
/// after one warm-up) [ns]. Every figure but the two tick times is a pure function of the inputs.
py::dict measure_stroke(const std::shared_ptr<eval::SweepScene>& s, const std::string& algorithm,
                        const py::object& params, int repetitions) {
  if (repetitions < 1) throw py::value_error("repetitions: " + std::to_string(repetitions) + ", must be >= 1");
  std::unique_ptr<servo::Renderer> r = make_renderer(algorithm, params, s->tau, "the scene's isovalue");
  // Ctrl-C stops it after the error replay or between two timed replays.
  const eval::ErrorFigures e = run_interruptible([&](const std::atomic<bool>& cancel) {
    eval::ErrorFigures f = eval::measure(*s, eval::playback(*r, *s));
    f.tick_ns_mean = eval::median_ns_per_tick(*r, *s, 1, repetitions, &cancel);
    return f;
  });
  py::dict d;
  d["tick_ns_mean"] = e.tick_ns_mean;
  d["tick_ns_p99"] = e.tick_ns_p99;
  d["surface_err_rms_m"] = e.surface_err_rms_m;
  d["angle_err_rms_deg"] = e.angle_err_rms_deg;
  d["force_err_rms_n"] = e.force_err_rms_n;
  d["max_force_step_n"] = e.max_force_step_n;
  d["max_force_step_slide_n"] = e.max_force_step_slide_n;
  d["contact_ticks"] = e.contact_ticks;
  d["pop_throughs"] = e.pop_throughs;
  d["ticks"] = s->hip.size();
  return d;
}

/// `with isotouch.Realtime("bench"):` the calling thread as `bench table1` times its replays:
/// SCHED_FIFO, pinned to one CPU where the system allows (servo::ScopedRealtime); restored at exit.
struct Realtime {
  explicit Realtime(std::string w) : who(std::move(w)) {}
  std::string who;
  std::optional<servo::ScopedRealtime> scope;
};

void bind_realtime(py::module_& m) {
  py::class_<Realtime>(m, "Realtime", R"(Context manager: the calling thread SCHED_FIFO and pinned to
one CPU (as `bench table1` times its replays) where the system allows; 'granted' says what it got.)")
      .def(py::init<std::string>(), py::arg("who") = "python")
      .def("__enter__", [](Realtime& r) -> Realtime& {
        r.scope.emplace(r.who);
        return r;
      }, py::return_value_policy::reference)
      .def("__exit__", [](Realtime& r, py::args) { r.scope.reset(); })
      .def_property_readonly("granted", [](const Realtime& r) {
        if (!r.scope) return std::string("not entered");
        const servo::RealtimeSetup& g = r.scope->setup();
        std::string s = std::string(g.fifo ? "SCHED_FIFO" : "default scheduler") + ", " +
                        (g.cpu >= 0 ? "CPU " + std::to_string(g.cpu) : std::string("unpinned"));
        return g.note.empty() ? s : s + "; " + g.note;
      });
}

void bind_params(py::module_& m) {
  py::enum_<core::InsideIs>(m, "InsideIs", "which side of tau is inside the object")
      .value("above", core::InsideIs::kAbove)
      .value("below", core::InsideIs::kBelow);
  py::enum_<servo::Variant>(m, "Variant").value("robust", servo::Variant::kRobust).value("paper", servo::Variant::kPaper);
  py::enum_<servo::Intersection>(m, "Intersection")
      .value("linear", servo::Intersection::kLinear)
      .value("secant", servo::Intersection::kSecant)
      .value("bisection", servo::Intersection::kBisection);
  py::enum_<servo::NormalSource>(m, "NormalSource")
      .value("samples", servo::NormalSource::kSamples)
      .value("central", servo::NormalSource::kCentral)
      .value("trilinear_exact", servo::NormalSource::kTrilinearExact);
  py::class_<servo::SurfaceFriction> friction(m, "SurfaceFriction",
                                              "§3.1 surface effects: SurfaceFriction(mu_s=0.3, mu_d=0.2, ...)");
  friction.def(py::init(&params_from_kwargs<servo::SurfaceFriction>))
      .def_readwrite("mu_s", &servo::SurfaceFriction::mu_s, "static friction coefficient")
      .def_readwrite("mu_d", &servo::SurfaceFriction::mu_d, "dynamic friction coefficient")
      .def_readwrite("viscous_n_s_per_m", &servo::SurfaceFriction::viscous_n_s_per_m, "viscous friction [N s/m]");
  def_params_repr(friction, "SurfaceFriction");
  using H = servo::HriParams;
  py::class_<H> hri(m, "HriParams", R"(HRI parameters (servo/hri.h): HriParams(tau=400.0, stiffness_n_per_m=500, ...)
takes any field as a keyword. tau is the isovalue in the volume's value units; K and B act
on device motion [N/m], [N s/m]; lengths in metres, grid-world.)");
  hri.def(py::init(&params_from_kwargs<H>))
      .def_readwrite("variant", &H::variant, "Variant.robust (default) or Variant.paper (Figure 2 as printed)")
      .def_readwrite("tau", &H::tau, "isovalue [volume value units]")
      .def_readwrite("inside", &H::inside, "InsideIs.above: values above tau are inside")
      .def_readwrite("stiffness_n_per_m", &H::stiffness_n_per_m, "K [N/m] of device motion")
      .def_readwrite("damping_n_s_per_m", &H::damping_n_s_per_m, "B [N s/m] along the penetration")
      .def_readwrite("plane_update_period", &H::plane_update_period, "n: the plane is recomputed every n ticks")
      .def_readwrite("rate_hz", &H::rate_hz, "servo rate [Hz]")
      .def_readwrite("force_limit_n", &H::force_limit_n, "|F| saturated here [N], direction kept")
      .def_readwrite("world_per_device", &H::world_per_device, "workspace scale: world [m] per device [m]")
      .def_readwrite("max_reach_m", &H::max_reach_m, "a HIP farther than this from the volume centre is a fault [m]")
      .def_readwrite("intersection", &H::intersection, "Intersection.linear, secant or bisection")
      .def_readwrite("intersection_steps", &H::intersection_steps, "secant / bisection steps")
      .def_readwrite("normal", &H::normal, "NormalSource: samples, central or trilinear_exact")
      .def_readwrite("friction", &H::friction, "SurfaceFriction")
      .def_readwrite("force_shading", &H::force_shading, "shading plane from the normal at the previous VHIP")
      .def_readwrite("recovery_time_s", &H::recovery_time_s, "> 0 turns recovery time on [s]")
      .def_readwrite("velocity_cutoff_hz", &H::velocity_cutoff_hz, "velocity filter cut-off [Hz]")
      .def_readwrite("max_speed_m_s", &H::max_speed_m_s, "fastest HIP motion believed [m/s]")
      .def_readwrite("march_budget", &H::march_budget, "most cells marched per tick")
      .def_readwrite("edit_period_s", &H::edit_period_s, "how often edits arrive [s]")
      .def_readwrite("tool_radius_m", &H::tool_radius_m, "spherical tool radius [m, world]; 0: a point")
      .def_readwrite("short_way", &H::short_way, "march each point once (same bits as the long way)");
  def_params_repr(hri, "HriParams");
  using B = servo::BaselineParams;
  py::class_<B> base(m, "BaselineParams", R"(Avila-Sobierajski and Blezek-Robb parameters (servo/baselines.h):
BaselineParams(tau=400.0, ...) takes any field as a keyword. tau in the volume's value units.)");
  base.def(py::init(&params_from_kwargs<B>))
      .def_readwrite("tau", &B::tau, "isovalue [volume value units]")
      .def_readwrite("inside", &B::inside, "InsideIs.above: values above tau are inside")
      .def_readwrite("stiffness_n_per_m", &B::stiffness_n_per_m, "K [N/m] of device motion")
      .def_readwrite("damping_n_s_per_m", &B::damping_n_s_per_m, "B [N s/m]")
      .def_readwrite("rate_hz", &B::rate_hz, "servo rate [Hz]")
      .def_readwrite("force_limit_n", &B::force_limit_n, "|F| saturated here [N], direction kept")
      .def_readwrite("world_per_device", &B::world_per_device, "workspace scale: world [m] per device [m]")
      .def_readwrite("max_reach_m", &B::max_reach_m, "a HIP farther than this from the volume centre is a fault [m]")
      .def_readwrite("inch_iterations", &B::inch_iterations, "Blezek-Robb: inching steps per tick")
      .def_readwrite("inch_step_voxels", &B::inch_step_voxels, "Blezek-Robb: longest inching step [voxels]")
      .def_readwrite("central_h_voxels", &B::central_h_voxels, "Blezek-Robb: central-difference half step [voxels]");
  def_params_repr(base, "BaselineParams");
}

void bind_field(py::module_& m) {
  py::class_<core::SampleField, FieldPtr> field(m, "Field", R"(A published snapshot: per voxel the value and its
gradient (grid-world frame, value units per m), as the renderers read it.)");
  def_grid_properties(field, "grid-world position of voxel (0, 0, 0) [m]")
      .def_readonly("version", &core::SampleField::version)
      .def_readonly("background", &core::SampleField::background, "value outside the grid (NaN: none)")
      .def_property_readonly("bricked", &core::SampleField::bricked)
      .def_property_readonly("samples", [](py::object self) { return sample_view(self, 0, 4); },
                             "(nz, ny, nx, 4) float32 (value, gx, gy, gz), read-only, no copy")
      .def_property_readonly("value", [](py::object self) { return sample_view(self, 0, 1); },
                             "(nz, ny, nx) float32 view of the values")
      .def_property_readonly("gradient", [](py::object self) { return sample_view(self, 1, 3); },
                             "(nz, ny, nx, 3) float32 view of the gradients [value / m]");
}

void bind_strokes(py::module_& m) {
  py::class_<eval::SweepScene, std::shared_ptr<eval::SweepScene>>(m, "StrokeScene", R"(A scene with one recorded
stroke, as `bench table1` and the sweeps replay it: samples, and the HIP per tick (grid-world [m]).)")
      .def_readonly("name", &eval::SweepScene::name)
      .def_readonly("description", &eval::SweepScene::description)
      .def_property_readonly("field", [](const eval::SweepScene& s) { return std::const_pointer_cast<core::SampleField>(s.field); })
      .def_property_readonly("hip", [](const eval::SweepScene& s) { return points_array(s.hip); }, "(N, 3) [m]")
      .def_readonly("tau", &eval::SweepScene::tau)
      .def_readonly("inside", &eval::SweepScene::inside)
      .def_readonly("rate_hz", &eval::SweepScene::rate_hz)
      .def_readonly("stiffness_n_per_m", &eval::SweepScene::stiffness_n_per_m)
      .def("table1_hri_params", [](const eval::SweepScene& s, servo::Variant v) { return table1_hri(s, v); },
           py::arg("variant") = servo::Variant::kRobust, "HRI as `bench table1` times it on this scene")
      .def("table1_baseline_params", &table1_baseline, "the baselines as `bench table1` times them")
      .def_readonly("voxel_m", &eval::SweepScene::voxel_m, "smallest spacing [m]")
      .def("reference_params", &eval::reference_params,
           "the reference renderer's HRI parameters on this scene (n = 1, exact root and gradient)");
  m.def("stroke_scene", &stroke_scene, py::arg("name"), py::arg("device") = "cpu", py::arg("tau") = py::none(),
        "sphere, box, three-spheres, knot, head, chest or a scene JSON path; samples on the CPU reference "
        "(device='cpu') or a Vulkan device ('' = default); tau: another isovalue for a scene file (volume "
        "units; ValueError for the exact shapes)");
}

}  // namespace

void bind_render(py::module_& m) {
  bind_params(m);
  bind_realtime(m);
  bind_field(m);
  bind_strokes(m);
  m.def("render", &render, py::arg("field"), py::arg("hip"), py::arg("algorithm") = "hri",
        py::arg("params") = py::none(), py::arg("dt") = 0.0, py::arg("planes") = false, py::arg("tau") = py::none(),
        R"(Run one renderer over a HIP trajectory.

field: an isotouch.Field; hip: (N, 3) HIP per tick, grid-world [m] (a non-finite row is a
fault tick: zero force, as the servo answers a device's NaN); algorithm 'hri' (params:
HriParams), 'avila' or 'blezek' (params: BaselineParams); tau: the isovalue (volume value
units), given here or as params.tau (both: they must agree; neither: ValueError, a Field does
not carry its isovalue); params of the other renderer: TypeError; dt: the period given each tick [s]
(0: the nominal 1 / rate). A fresh renderer runs every call, the GIL released but for a
signal check every 16384 ticks (Ctrl-C raises KeyboardInterrupt within one such chunk).
Returns a dict of arrays: force (N, 3) [N] device axes, vhip (N, 3) [m], contact, plane_update,
saturated, fault (N,) bool; with planes=True also the plane after each tick, plane_n (N, 3) unit
outward normal and plane_p (N, 3) [m] (HRI; zero for the baselines), plane_valid (N,) bool, and
penetration (N,) [m].)");
  m.def("measure_stroke", &measure_stroke, py::arg("scene"), py::arg("algorithm") = "hri",
        py::arg("params") = py::none(), py::arg("repetitions") = 5,
        R"(One configuration on a StrokeScene's recorded stroke, as `isotouch report` measures it.
params.tau, if given, must be the scene's isovalue (scene.tau; None: the scene's).

Returns a dict: tick_ns_mean (median of `repetitions` whole replays) and tick_ns_p99 [ns],
surface_err_rms_m [m], angle_err_rms_deg, force_err_rms_n [N], max_force_step_n and
max_force_step_slide_n [N], contact_ticks, pop_throughs, ticks. All but the tick times depend
on the inputs only. The GIL is released while it runs; Ctrl-C raises KeyboardInterrupt between
two replays.)");
  m.def("cpp_ns_per_tick", &cpp_ns_per_tick, py::arg("field"), py::arg("hip"), py::arg("algorithm") = "hri",
        py::arg("params") = py::none(), py::arg("warmup") = 3, py::arg("repetitions") = 21, py::arg("tau") = py::none(),
        "median C++ time per Renderer::tick over the trajectory [ns] (eval::median_ns_per_tick, as bench table1); "
        "GIL released, Ctrl-C raises KeyboardInterrupt between two replays");
}

}  // namespace isotouch::python
